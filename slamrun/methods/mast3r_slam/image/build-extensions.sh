#!/usr/bin/env bash
# MASt3R-SLAM's compiled parts, built in the image without a GPU (slamrun/methods/recipes/common/build-torch-extension.sh:
# the CUDA 13.0 compiler from PyPI's wheels, for the compute capabilities of ARCH_LIST): lietorch_backends in
# thirdparty/lietorch, mast3r_slam_backends in the tree, croco's curope (its RoPE kernels), then asmk's hamming (plain C,
# from the C file its authors generated with Cython 3.0.11). The pinned archives are unpacked into DEST (lietorch's
# into thirdparty/lietorch, which MASt3R-SLAM's pyproject installs from GitHub) and patched with
# slamrun/methods/mast3r_slam/image/patches.py (the same patches as `slamrun native-build mast3r_slam`). Each step fails
# loudly.
# usage: build-extensions.sh MAST3R_SLAM_ARCHIVE LIETORCH_ARCHIVE DEST "ARCH_LIST" JOBS PATCHES_PY
set -euo pipefail
archive=$1 lietorch=$2 dest=$3 arch=$4 jobs=$5 patches=$6
compile=$(dirname "$0")/../common/build-torch-extension.sh
py=/opt/venv/bin/python

mkdir -p "$dest"
tar -xzf "$archive" -C "$dest"
tree=$(find "$dest" -mindepth 1 -maxdepth 1 -type d -name 'MASt3R-SLAM-*')
tar -xzf "$lietorch" -C "$tree/thirdparty"
mv "$tree"/thirdparty/lietorch-* "$tree/thirdparty/lietorch"
python3 "$patches" "$tree"

bash "$compile" "$tree/thirdparty/lietorch" "$arch" "$jobs" lietorch_backends
bash "$compile" "$tree" "$arch" "$jobs" mast3r_slam_backends
bash "$compile" "$tree/thirdparty/mast3r/dust3r/croco/models/curope" "$arch" "$jobs" curope
(cd "$tree/thirdparty/mast3r/asmk" && "$py" setup.py build_ext --inplace && rm -rf build \
  && strip --strip-debug asmk/hamming.*.so)
rmdir "$tree/thirdparty/lietorch/eigen" "$tree/thirdparty/eigen" 2>/dev/null || true  # empty submodule folders
cd "$tree"
PYTHONPATH="$tree:$tree/thirdparty/mast3r:$tree/thirdparty/mast3r/asmk:$tree/thirdparty/lietorch" "$py" -c \
  "import torch, lietorch, mast3r_slam_backends, asmk.hamming, main; from models.curope import cuRoPE2D; \
print('MASt3R-SLAM imports with torch', torch.__version__)"
