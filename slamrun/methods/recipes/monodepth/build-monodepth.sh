#!/bin/sh
# monodepth-cpp (yan99033/monodepth-cpp @ 1ea2fc3) against the wheel's TensorFlow 2 C++ (see tf-from-wheel.sh):
# its static library (the only C++17, TensorFlow-facing code; its header monodepth.h is OpenCV/std only), the
# stand-in model generator and the model checker (make_standin_model.cc, check_model.cc beside this script).
# usage: build-monodepth.sh ARCHIVE DEST TENSORFLOW_ROOT MARCH JOBS
set -eu
here=$(dirname "$0")
archive=$1; dest=$2; tf=$3; march=$4; jobs=$5
"$here/../common/unpack.sh" "$archive" "$dest"
python3 "$here/patches.py" "$dest"
"$here/../common/portable-march.sh" "$dest" "$march"
cmake -S "$dest" -B "$dest/build" -DCMAKE_BUILD_TYPE=Release -DTENSORFLOW_ROOT="$tf" \
  -DCMAKE_CXX_FLAGS="-march=$march -Wno-deprecated-declarations -Wno-interference-size"
make -C "$dest/build" -j"$jobs" monodepth_static
tflibs="$tf/libtensorflow_cc.so.2 $tf/libtensorflow_framework.so.2 -Wl,-rpath,$tf"
g++ -std=c++17 -O2 -march="$march" -Wno-deprecated-declarations -Wno-interference-size -I"$tf/include" "$here/make_standin_model.cc" \
  -o "$dest/build/make_standin_model" $tflibs
g++ -std=c++14 -O2 -march="$march" -I"$dest/include" -I/usr/include/opencv4 "$here/check_model.cc" \
  -o "$dest/build/check_model" "$dest/build/libmonodepth_static.a" $tflibs -lopencv_imgproc -lopencv_core
echo "build-monodepth: $dest/build/libmonodepth_static.a, make_standin_model, check_model"
