#!/usr/bin/env bash
# Build an ORB-SLAM2-layout tree (ORB-SLAM2, DF-ORB-SLAM): Thirdparty DBoW2 and g2o, the library and one
# example TARGET (a path below the tree, e.g. Examples/Monocular/mono_tum), stripped, and the Debian packages
# owning the libraries it loads written to /opt/runtime-packages.txt.
# usage: build-orb-slam2.sh ROOT TARGET JOBS
# Upstream's build.sh has no `set -e`; these are its steps, each one failing loudly. DBoW2 and g2o are linked by
# their paths in the tree (Thirdparty/*/lib) and built with the library's C++ standard (their CMakeLists set none).
set -euo pipefail
root=$1 target=$2 jobs=${3:-2}
cd "$root"
for lib in DBoW2 g2o; do
  cmake -S "Thirdparty/$lib" -B "Thirdparty/$lib/build" -DCMAKE_BUILD_TYPE=Release -DCMAKE_CXX_FLAGS=-std=c++14
  make -C "Thirdparty/$lib/build" -j"$jobs"
  test -f "Thirdparty/$lib/lib/lib$lib.so"
done
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release
make -C build -j"$jobs" "$(basename "$target")"
test -x "$target"
strip "$target"
python3 "$(dirname "$0")/runtime_packages.py" "$target" > /opt/runtime-packages.txt
