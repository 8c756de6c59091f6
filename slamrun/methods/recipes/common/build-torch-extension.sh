#!/usr/bin/env bash
# One folder's PyTorch CUDA extensions (its setup.py's), compiled in an image without a GPU by the PyTorch of /opt/venv
# with the CUDA 13.0 compiler from PyPI's wheels (nvidia/cu13: nvcc, crt, nvvm, cccl beside the runtime's headers and
# libraries), for the compute capabilities of ARCH_LIST, in place (`setup.py build_ext --inplace`); the build folder
# (object files) is removed, the debug sections are stripped (Debian's Python compiles with -g), and the extensions
# MODULE... must import beside torch. Each step fails loudly. Eigen: Debian's /usr/include/eigen3.
# usage: build-torch-extension.sh SETUP_DIR "ARCH_LIST" JOBS MODULE...
set -euo pipefail
dir=$1 arch=$2 jobs=$3
shift 3
py=/opt/venv/bin/python
site=$($py -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')
cuda=$site/nvidia/cu13
[ -x "$cuda/bin/nvcc" ] || { echo "build-torch-extension: no nvcc in $cuda/bin (the nvidia-cuda-nvcc wheel)" >&2; exit 1; }
[ -f "$cuda/lib/libcudart.so" ] || ln -s libcudart.so.13 "$cuda/lib/libcudart.so"  # what the linker's -lcudart finds
cd "$dir"
start=$(date +%s)
# NVCC_APPEND_FLAGS: nvcc compiles one file's targets in parallel (one heavy .cu file takes most of the time)
CUDA_HOME=$cuda TORCH_CUDA_ARCH_LIST="$arch" MAX_JOBS=$jobs EIGEN_INCLUDE_DIR=/usr/include/eigen3 \
  NVCC_APPEND_FLAGS="--threads $jobs" PATH="$cuda/bin:/opt/venv/bin:$PATH" "$py" setup.py build_ext --inplace
echo "build-torch-extension: $* compiled in $dir for compute capability $arch in $(( $(date +%s) - start )) s" \
  "with $jobs jobs"
rm -rf build
strip --strip-debug ./*.so
ls -la ./*.so
modules=$(IFS=,; echo "$*")
"$py" -c "import torch, $modules; print('$modules import with torch', torch.__version__)"
