# pangolin: debian-build with Pangolin v0.6 in /usr/local (ORB-SLAM2-era code is C++11; newer Pangolin needs C++17),
# for the methods that link it (DSO, LDSO, the ORB-SLAM family); no viewer is ever opened (nogui=1, viewer off).
# Put ahead of a recipe that starts FROM it, with recipes/debian/stages.Dockerfile ahead of both.
FROM debian-build AS pangolin
COPY sources/pangolin-0.6.tar.gz /opt/slamrun-build/sources/
RUN /opt/slamrun-build/common/build-pangolin.sh /opt/slamrun-build/sources/pangolin-0.6.tar.gz "$MARCH" "$JOBS"
