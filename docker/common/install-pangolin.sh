#!/bin/sh
# Build and install Pangolin at a pinned version (v0.5/v0.6: ORB-SLAM2-era code is C++11, newer Pangolin
# needs C++17). usage: install-pangolin.sh REPO COMMIT MARCH JOBS
set -eu
git clone "$1" /opt/Pangolin
cd /opt/Pangolin
git checkout "$2"
"$(dirname "$0")/portable-march.sh" /opt/Pangolin "$3"
mkdir build && cd build
cmake .. -DCMAKE_BUILD_TYPE=Release -DBUILD_EXAMPLES=OFF -DBUILD_TESTS=OFF
make -j"$4" && make install && ldconfig
