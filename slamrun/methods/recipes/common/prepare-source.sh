#!/bin/sh
# A method's source tree, ready to build: its archive (sources/METHOD.tar.gz of the build context) unpacked into
# DEST, the method's patches.py applied (with any further arguments after DEST) and -march=native replaced by MARCH.
# usage: prepare-source.sh METHOD DEST [PATCH_ARGUMENT...]   (MARCH from the environment, debian-build's)
set -eu
method=$1 dest=$2
shift 2
build=/opt/slamrun-build
"$build/common/unpack.sh" "$build/sources/$method.tar.gz" "$dest"
python3 "$build/$method/patches.py" "$dest" "$@"
"$build/common/portable-march.sh" "$dest" "${MARCH:-x86-64-v2}"
