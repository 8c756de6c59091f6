#!/usr/bin/env bash
# DPVO's CUDA extensions (cuda_corr, cuda_ba, lietorch_backends) compiled in the image without a GPU
# (slamrun/methods/recipes/common/build-torch-extension.sh: the CUDA 13.0 compiler from PyPI's wheels, for the compute
# capabilities of ARCH_LIST). The pinned archive is unpacked into DEST and patched with
# slamrun/methods/dpvo/image/patches.py (the same patches as `slamrun native-build dpvo`); its thirdparty folder
# (Eigen, served by Debian's headers; the loop-closure code slamrun does not build) is removed. Each step fails loudly.
# usage: build-extensions.sh ARCHIVE DEST "ARCH_LIST" JOBS PATCHES_PY
set -euo pipefail
archive=$1 dest=$2 arch=$3 jobs=$4 patches=$5
compile=$(dirname "$0")/../common/build-torch-extension.sh

mkdir -p "$dest"
tar -xzf "$archive" -C "$dest"
tree=$(find "$dest" -mindepth 1 -maxdepth 1 -type d -name 'DPVO-*')
python3 "$patches" "$tree"
bash "$compile" "$tree" "$arch" "$jobs" cuda_corr cuda_ba lietorch_backends
rm -rf "$tree/thirdparty"
