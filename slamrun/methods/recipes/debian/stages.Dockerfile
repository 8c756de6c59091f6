# The stages the CPU methods' images share (each slamrun/methods/*/image/Dockerfile of a compiled method starts
# `FROM debian-build`, `FROM pangolin` or `FROM monodepth AS build` and ends `FROM debian-runtime`): `slamrun images`
# puts this file ahead of a recipe that names one of its stages (slamrun/images/build.py, recipe_text), so every
# image is built from one text of these steps and an engine that built one serves the others' from its cache.
# debian-build: Debian 12 with the compiler, CMake and the -dev packages the methods build against (the union of
# what each needs: a method's CMake finds only what it asks for; Pangolin's options are all set, build-pangolin.sh),
# slamrun's build scripts in /opt/slamrun-build/common, and MARCH (the portable CPU target every tree is compiled
# for) and JOBS (make's parallelism) in the environment of every step after it.
# debian-runtime: a bare Debian 12 with the user slam (uid 1000) and /work; a method's last stage copies what its
# build stage put together in /opt/runtime (stage-runtime.sh) and installs it (install-runtime.sh).
FROM debian:bookworm-slim AS debian-build
RUN apt-get update && DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends \
      build-essential cmake pkg-config python3 libeigen3-dev libsuitesparse-dev libboost-system-dev \
      libboost-thread-dev libboost-serialization-dev libssl-dev libopencv-dev libgoogle-glog-dev libzip-dev \
      zlib1g-dev libglew-dev libgl1-mesa-dev libx11-dev \
 && rm -rf /var/lib/apt/lists/*
COPY recipes/common /opt/slamrun-build/common
ARG MARCH=x86-64-v2
ARG JOBS=2
ENV MARCH=$MARCH JOBS=$JOBS

FROM debian:bookworm-slim AS debian-runtime
COPY recipes/common/install-runtime.sh /usr/local/sbin/slamrun-install-runtime
RUN useradd --create-home --uid 1000 slam
WORKDIR /work
