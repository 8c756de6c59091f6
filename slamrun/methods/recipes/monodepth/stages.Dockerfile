# monodepth: debian-build with TensorFlow's C++ libraries and headers from PyPI's tensorflow-cpu 2.21.0 wheel for
# CPython 3.11 (no Bazel, no TF 1.6; the runner fetches the wheel on the host into the context's pypi/) in
# /opt/tensorflow, and yan99033/monodepth-cpp built against them in /opt/monodepth-cpp: what CNN-DSO and CNN-SVO
# infer MonoDepth's depth with, on the CPU. Their frozen graph is each method's own step (model.sh).
FROM debian-build AS monodepth
ARG TF_WHEEL=tensorflow_cpu-2.21.0-cp311-cp311-manylinux_2_27_x86_64.whl
ARG TF_WHEEL_SHA256=2b847d217b02ee7731ed91431daf3250daa0196c3c94614d23be27232e6e5b6c
COPY pypi/tensorflow_cpu-2.21.0-cp311-cp311-manylinux_2_27_x86_64.whl /opt/slamrun-build/pypi/
COPY recipes/monodepth /opt/slamrun-build/monodepth
RUN /opt/slamrun-build/monodepth/tf-from-wheel.sh "/opt/slamrun-build/pypi/$TF_WHEEL" "$TF_WHEEL_SHA256" /opt/tensorflow \
 && rm -rf /opt/slamrun-build/pypi
COPY sources/monodepth-cpp.tar.gz /opt/slamrun-build/sources/
RUN /opt/slamrun-build/monodepth/build-monodepth.sh /opt/slamrun-build/sources/monodepth-cpp.tar.gz \
      /opt/monodepth-cpp /opt/tensorflow "$MARCH" "$JOBS"
