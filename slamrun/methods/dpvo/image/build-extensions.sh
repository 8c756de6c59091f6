#!/usr/bin/env bash
# DPVO's CUDA extensions (cuda_corr, cuda_ba, lietorch_backends) compiled in the image without a GPU, by the
# PyTorch of /opt/venv with the CUDA 13.0 compiler from PyPI's wheels (nvidia/cu13: nvcc, crt, nvvm, cccl beside
# the runtime's headers and libraries), for the compute capabilities of ARCH_LIST. The pinned archive is unpacked
# into DEST and patched with slamrun/methods/dpvo/image/patches.py (the same patches as `slamrun native-build dpvo`); the build
# folder (object files) is removed. Each step fails loudly.
# usage: build-extensions.sh ARCHIVE DEST "ARCH_LIST" JOBS PATCHES_PY
set -euo pipefail
archive=$1 dest=$2 arch=$3 jobs=$4 patches=$5
py=/opt/venv/bin/python
site=$($py -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')
cuda=$site/nvidia/cu13
[ -x "$cuda/bin/nvcc" ] || { echo "build-extensions: no nvcc in $cuda/bin (the nvidia-cuda-nvcc wheel)" >&2; exit 1; }
[ -f "$cuda/lib/libcudart.so" ] || ln -s libcudart.so.13 "$cuda/lib/libcudart.so"  # what the linker's -lcudart finds
"$cuda/bin/nvcc" --version | tail -2

mkdir -p "$dest"
tar -xzf "$archive" -C "$dest"
tree=$(find "$dest" -mindepth 1 -maxdepth 1 -type d -name 'DPVO-*')
python3 "$patches" "$tree"

cd "$tree"
start=$(date +%s)
# NVCC_APPEND_FLAGS: nvcc compiles one file's targets in parallel (lietorch_gpu.cu alone takes most of the time)
CUDA_HOME=$cuda TORCH_CUDA_ARCH_LIST="$arch" MAX_JOBS=$jobs EIGEN_INCLUDE_DIR=/usr/include/eigen3 \
  NVCC_APPEND_FLAGS="--threads $jobs" PATH="$cuda/bin:/opt/venv/bin:$PATH" "$py" setup.py build_ext --inplace
echo "build-extensions: compiled for compute capability $arch in $(( $(date +%s) - start )) s with $jobs jobs"
rm -rf build thirdparty
strip --strip-debug ./*.so  # Debian's Python compiles with -g
ls -la ./*.so
"$py" -c "import torch, cuda_corr, cuda_ba, lietorch_backends; print('extensions import with torch', torch.__version__)"
