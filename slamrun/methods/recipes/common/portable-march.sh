#!/bin/sh
# Replace -march=native with a portable target in every CMake file of a source tree, and fail if any
# remains: an image built on one CPU must not die with SIGILL on another.
# usage: portable-march.sh SRC_DIR [MARCH]   (MARCH defaults to x86-64-v2)
set -eu
src=$1
march=${2:-x86-64-v2}
find "$src" \( -name CMakeLists.txt -o -name '*.cmake' -o -name Makefile \) -print0 |
  xargs -0 -r sed -i "s/-march=native/-march=$march/g; s/-mtune=native/-mtune=generic/g"
if grep -rIl --include=CMakeLists.txt --include='*.cmake' --include=Makefile -e '-march=native' "$src"; then
  echo "portable-march: -march=native is still set in the files above" >&2
  exit 1
fi
echo "portable-march: $src builds for -march=$march"
