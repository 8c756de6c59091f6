#!/bin/sh
# LDSO's vocabulary, by the build's choice (slamrun images decides and says it; the image's label records it):
#   source   vocab/orbvoc.dbow3 of the source tree (the authors' file; the study's setting)
#   given    the file in the build context's inputs/vocabulary/
#   trained  trained now with LDSO's DBoW3 on the frames in inputs/train-frames/ (synthetic; not the study's)
# usage: vocabulary.sh CHOICE LDSO_ROOT INPUTS
set -eu
choice=$1; root=$2; inputs=$3
out=$root/vocab/orbvoc.dbow3
mkdir -p "$root/vocab"
case "$choice" in
  source)
    test -s "$out" || { echo "vocabulary: the source has no vocab/orbvoc.dbow3 (build again with --vocabulary FILE)" >&2; exit 1; } ;;
  given)
    test -s "$inputs/vocabulary/orbvoc.dbow3" || { echo "vocabulary: no file in inputs/vocabulary/" >&2; exit 1; }
    cp "$inputs/vocabulary/orbvoc.dbow3" "$out" ;;
  trained)
    ls "$inputs"/train-frames/*.jpg >/dev/null 2>&1 || { echo "vocabulary: no frames in inputs/train-frames/" >&2; exit 1; }
    g++ -O2 -std=c++11 -I"$root/thirdparty" -isystem /usr/include/opencv4 /opt/slamrun-build/ldso/train_vocabulary.cc \
      -o /tmp/train_vocabulary -L"$root/thirdparty/DBoW3/build/src" -Wl,-rpath,"$root/thirdparty/DBoW3/build/src" \
      -lDBoW3 -lopencv_core -lopencv_imgcodecs -lopencv_features2d
    /tmp/train_vocabulary "$out" "$inputs"/train-frames/*.jpg ;;
  *)
    echo "vocabulary: VOCABULARY must be source, given or trained (got '$choice'); build with slamrun images" >&2; exit 1 ;;
esac
echo "vocabulary: $choice -> $out ($(wc -c < "$out") bytes)"
