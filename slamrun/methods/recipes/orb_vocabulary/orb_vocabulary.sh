#!/bin/sh
# The DBoW2 text vocabulary of an ORB-SLAM2-family image (ORB-SLAM2, DF-ORB-SLAM), by the build's choice
# (slamrun images decides and says it; the image's label records it). Result: ROOT/Vocabulary/ORBvoc.txt.
#   source   Vocabulary/ORBvoc.txt.tar.gz of the source tree (the authors' file, k=10 L=6; the study's setting)
#   given    the one file in the build context's inputs/vocabulary/ (ORBvoc.txt, or a .tar.gz holding it)
#   trained  trained now on inputs/train-frames/*.jpg with the tree's own DBoW2 and ORBextractor
#            (train_orb_vocabulary.cc beside this script; synthetic frames, k=10 L=5; not the study's)
# Must run after the tree's Thirdparty/DBoW2 is built (trained links its lib/libDBoW2.so).
# usage: orb_vocabulary.sh CHOICE ROOT INPUTS
set -eu
choice=$1; root=$2; inputs=$3
here=$(dirname "$0")
out=$root/Vocabulary/ORBvoc.txt
mkdir -p "$root/Vocabulary"

# the first line of a DBoW2 text vocabulary: "k L scoring weighting"
check() {
  head -n 1 "$1" | grep -Eq '^[0-9]+ +[0-9]+ +[0-9]+ +[0-9]+ *$' ||
    { echo "vocabulary: $1 is not a DBoW2 text vocabulary (first line: $(head -c 60 "$1" | head -n 1))" >&2; exit 1; }
}

case "$choice" in
  source)
    test -s "$root/Vocabulary/ORBvoc.txt.tar.gz" ||
      { echo "vocabulary: the source has no Vocabulary/ORBvoc.txt.tar.gz (build again with --vocabulary FILE, or let it train one)" >&2; exit 1; }
    tar -xzf "$root/Vocabulary/ORBvoc.txt.tar.gz" -C "$root/Vocabulary" --no-same-owner
    rm "$root/Vocabulary/ORBvoc.txt.tar.gz" ;;
  given)
    n=$(find "$inputs/vocabulary" -maxdepth 1 -type f 2>/dev/null | wc -l)
    [ "$n" -eq 1 ] || { echo "vocabulary: expected one file in inputs/vocabulary/, found $n" >&2; exit 1; }
    given=$(find "$inputs/vocabulary" -maxdepth 1 -type f)
    if [ "$(od -An -tx1 -N2 "$given" | tr -d ' ')" = "1f8b" ]; then   # gzip: the repository's ORBvoc.txt.tar.gz
      tar -xzf "$given" -C "$root/Vocabulary" --no-same-owner ORBvoc.txt
    else
      cp "$given" "$out"
    fi ;;
  trained)
    ls "$inputs"/train-frames/*.jpg >/dev/null 2>&1 || { echo "vocabulary: no frames in inputs/train-frames/" >&2; exit 1; }
    test -f "$root/Thirdparty/DBoW2/lib/libDBoW2.so" || { echo "vocabulary: build Thirdparty/DBoW2 first" >&2; exit 1; }
    g++ -O2 -std=c++14 -I"$root" -I"$root/include" -isystem /usr/include/opencv4 \
      "$here/train_orb_vocabulary.cc" "$root/src/ORBextractor.cc" -o /tmp/train_orb_vocabulary \
      -L"$root/Thirdparty/DBoW2/lib" -Wl,-rpath,"$root/Thirdparty/DBoW2/lib" -lDBoW2 \
      -lopencv_core -lopencv_imgproc -lopencv_features2d -lopencv_imgcodecs
    /tmp/train_orb_vocabulary "$out" "$inputs"/train-frames/*.jpg
    rm /tmp/train_orb_vocabulary ;;
  *)
    echo "vocabulary: VOCABULARY must be source, given or trained (got '$choice'); build with slamrun images" >&2; exit 1 ;;
esac
test -s "$out" || { echo "vocabulary: $out missing after '$choice'" >&2; exit 1; }
check "$out"
echo "vocabulary: $choice -> $out ($(wc -c < "$out") bytes, header '$(head -n 1 "$out")')"
