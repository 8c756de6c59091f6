#!/usr/bin/env bash
# DROID-SLAM's CUDA extensions compiled in the image without a GPU (slamrun/methods/recipes/common/build-torch-extension.sh: the CUDA
# 13.0 compiler from PyPI's wheels, for the compute capabilities of ARCH_LIST): lietorch_backends in
# thirdparty/lietorch, then droid_backends in the tree. The pinned archives are unpacked into DEST (lietorch's into
# DROID-SLAM's empty submodule folder, as `git submodule update` would) and patched with slamrun/methods/droid_slam/image/patches.py
# (the same patches as `slamrun native-build droid_slam`). Each step fails loudly.
# usage: build-extensions.sh DROID_ARCHIVE LIETORCH_ARCHIVE DEST "ARCH_LIST" JOBS PATCHES_PY
set -euo pipefail
droid=$1 lietorch=$2 dest=$3 arch=$4 jobs=$5 patches=$6
compile=$(dirname "$0")/../common/build-torch-extension.sh

mkdir -p "$dest"
tar -xzf "$droid" -C "$dest"
tree=$(find "$dest" -mindepth 1 -maxdepth 1 -type d -name 'DROID-SLAM-*')
rmdir "$tree/thirdparty/lietorch"  # the submodule's empty folder
tar -xzf "$lietorch" -C "$tree/thirdparty"
mv "$tree"/thirdparty/lietorch-* "$tree/thirdparty/lietorch"
rm -rf "$tree/thirdparty/pytorch_scatter"  # empty: torch_scatter's two functions come from droid_slam/_scatter.py
python3 "$patches" "$tree"

bash "$compile" "$tree/thirdparty/lietorch" "$arch" "$jobs" lietorch_backends
bash "$compile" "$tree" "$arch" "$jobs" droid_backends
rmdir "$tree/thirdparty/lietorch/eigen"  # the Eigen submodule's empty folder: Debian's headers served
cd "$tree"
PYTHONPATH="$tree/thirdparty/lietorch:$tree/droid_slam:$tree" /opt/venv/bin/python -c \
  "import torch, lietorch, droid_backends, droid_net; print('DROID-SLAM imports with torch', torch.__version__)"
