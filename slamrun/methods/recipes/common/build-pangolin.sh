#!/bin/sh
# Build and install Pangolin v0.5/v0.6 from its source archive into /usr/local (ORB-SLAM2-era code is C++11;
# newer Pangolin needs C++17). Only what the methods link: OpenGL, GLEW, X11, Eigen; every video, image and
# Python option off, so no optional library is picked up from whatever -dev packages are installed.
# gcc 12 no longer includes <limits>/<cstdint> transitively, which v0.6's sources rely on.
# usage: build-pangolin.sh ARCHIVE MARCH JOBS
set -eu
here=$(dirname "$0")
"$here/unpack.sh" "$1" /opt/Pangolin
"$here/portable-march.sh" /opt/Pangolin "$2"
off=""
for opt in PYTHON FFMPEG LIBDC1394 V4L LIBREALSENSE LIBREALSENSE2 OPENNI OPENNI2 LIBUVC UVC_MEDIAFOUNDATION \
           DEPTHSENSE TELICAM PLEORA LIBPNG LIBJPEG LIBTIFF LIBOPENEXR ZSTD LZ4 TOON; do
  off="$off -DBUILD_PANGOLIN_$opt=OFF"
done
mkdir -p /opt/Pangolin/build && cd /opt/Pangolin/build && cmake .. -DCMAKE_BUILD_TYPE=Release -DBUILD_EXAMPLES=OFF -DBUILD_TESTS=OFF \
  -DBUILD_TOOLS=OFF -DBUILD_PYPANGOLIN_MODULE=OFF $off -DCMAKE_CXX_FLAGS="-include cstdint -include limits"
make -C /opt/Pangolin/build -j"$3"
make -C /opt/Pangolin/build install
ldconfig
cd / && rm -rf /opt/Pangolin
echo "build-pangolin: installed $(ls /usr/local/lib | grep -c pangolin) Pangolin librar(ies) into /usr/local/lib"
