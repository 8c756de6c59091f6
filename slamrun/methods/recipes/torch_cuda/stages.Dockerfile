# The stages DPVO's and DROID-SLAM's images share (slamrun/methods/{dpvo,droid_slam}/image/Dockerfile start `FROM
# torch-cuda AS build` and end `FROM torch-runtime`): `slamrun images` puts this file ahead of a recipe that names
# one of its stages (slamrun/images/build.py, recipe_text), so both images are built from one text of these steps and
# an engine that built one serves the other's from its cache.
# torch-cuda: Debian 12 (debian:bookworm-slim) and its Python 3.11 in /opt/venv with PyTorch 2.11.0, the PyPI build
# for CUDA 13.0, the CUDA 13.0 libraries its cuda-toolkit 13.0.2 pins, NumPy and OpenCV (headless); then the CUDA 13.0
# compiler from PyPI (nvidia-cuda-nvcc, -crt, -nvvm, -cccl 13.0 as cuda-toolkit 13.0.2 pins them, and ninja), all in
# the wheels' nvidia/cu13 folder (CUDA_HOME), with g++ and Eigen: what compiles a PyTorch CUDA extension WITHOUT a
# GPU. Every file is pinned by name and SHA-256 in slamrun/images/sources.py (DPVO_TORCH, DPVO_TOOLCHAIN, each pin
# explained there; requirements*.txt beside this file are generated from them), fetched by the host into the
# context's pypi/ (checked) and installed with pip --no-index --require-hashes: the build reaches no PyPI.
# torch-runtime: a bare Debian 12 with its python3 and that environment without the compiler (nor triton,
# torch.compile's compiler, 641 MB, which neither method calls), PYTHONPATH=/opt/slamrun for slamrun's process, and
# the user slam (uid 1000).
FROM debian:bookworm-slim AS torch-cuda
RUN apt-get update && DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends \
      python3 python3-dev python3-venv g++ libeigen3-dev \
 && rm -rf /var/lib/apt/lists/*
# PyTorch and what runs beside it: pip itself from its wheel, then every file by version and hash
COPY \
     pypi/pip-26.3-py3-none-any.whl \
     pypi/torch-2.11.0-cp311-cp311-manylinux_2_28_x86_64.whl \
     pypi/cuda_toolkit-13.0.2-py2.py3-none-any.whl \
     pypi/nvidia_cuda_runtime-13.0.96-py3-none-manylinux2014_x86_64.manylinux_2_17_x86_64.whl \
     pypi/nvidia_cuda_nvrtc-13.0.88-py3-none-manylinux2010_x86_64.manylinux_2_12_x86_64.whl \
     pypi/nvidia_cuda_cupti-13.0.85-py3-none-manylinux_2_25_x86_64.whl \
     pypi/nvidia_cublas-13.1.0.3-py3-none-manylinux_2_27_x86_64.whl \
     pypi/nvidia_cufft-12.0.0.61-py3-none-manylinux2014_x86_64.manylinux_2_17_x86_64.whl \
     pypi/nvidia_cufile-1.15.1.6-py3-none-manylinux2014_x86_64.manylinux_2_17_x86_64.whl \
     pypi/nvidia_curand-10.4.0.35-py3-none-manylinux_2_27_x86_64.whl \
     pypi/nvidia_cusolver-12.0.4.66-py3-none-manylinux_2_27_x86_64.whl \
     pypi/nvidia_cusparse-12.6.3.3-py3-none-manylinux2014_x86_64.manylinux_2_17_x86_64.whl \
     pypi/nvidia_nvjitlink-13.0.88-py3-none-manylinux2010_x86_64.manylinux_2_12_x86_64.whl \
     pypi/nvidia_nvtx-13.0.85-py3-none-manylinux1_x86_64.manylinux_2_5_x86_64.whl \
     pypi/nvidia_cudnn_cu13-9.19.0.56-py3-none-manylinux_2_27_x86_64.whl \
     pypi/nvidia_cusparselt_cu13-0.8.0-py3-none-manylinux2014_x86_64.whl \
     pypi/nvidia_nccl_cu13-2.28.9-py3-none-manylinux_2_18_x86_64.whl \
     pypi/nvidia_nvshmem_cu13-3.4.5-py3-none-manylinux2014_x86_64.manylinux_2_17_x86_64.whl \
     pypi/cuda_bindings-13.5.0-cp311-cp311-manylinux_2_24_x86_64.manylinux_2_28_x86_64.whl \
     pypi/cuda_pathfinder-1.9.1-py3-none-any.whl \
     pypi/triton-3.6.0-cp311-cp311-manylinux_2_27_x86_64.manylinux_2_28_x86_64.whl \
     pypi/filelock-4.3.1-py3-none-any.whl \
     pypi/fsspec-2026.9.0-py3-none-any.whl \
     pypi/jinja2-3.1.6-py3-none-any.whl \
     pypi/markupsafe-3.0.4-cp311-cp311-manylinux2014_x86_64.manylinux_2_17_x86_64.manylinux_2_28_x86_64.whl \
     pypi/mpmath-1.3.0-py3-none-any.whl \
     pypi/networkx-3.6.1-py3-none-any.whl \
     pypi/setuptools-81.0.0-py3-none-any.whl \
     pypi/sympy-1.14.0-py3-none-any.whl \
     pypi/typing_extensions-4.16.0-py3-none-any.whl \
     pypi/numpy-2.2.6-cp311-cp311-manylinux_2_17_x86_64.manylinux2014_x86_64.whl \
     pypi/opencv_python_headless-4.11.0.86-cp37-abi3-manylinux_2_17_x86_64.manylinux2014_x86_64.whl \
     /opt/slamrun-build/pypi/
COPY recipes/torch_cuda/requirements.txt /opt/slamrun-build/
RUN python3 -m venv --without-pip /opt/venv \
 && cd /opt/slamrun-build/pypi \
 && /opt/venv/bin/python pip-26.3-py3-none-any.whl/pip install --no-index --no-cache-dir --no-deps \
      pip-26.3-py3-none-any.whl \
 && /opt/venv/bin/python -m pip install --no-index --no-cache-dir --find-links . --require-hashes \
      -r /opt/slamrun-build/requirements.txt \
 && cd / && rm -rf /opt/slamrun-build/pypi \
 && /opt/venv/bin/python -c "import torch, numpy, cv2; \
print('torch', torch.__version__, 'CUDA', torch.version.cuda, 'numpy', numpy.__version__, 'cv2', cv2.__version__)"
# the CUDA 13.0 compiler, into the same nvidia/cu13 folder as the runtime's headers and libraries
COPY \
     pypi/nvidia_cuda_nvcc-13.0.88-py3-none-manylinux2014_x86_64.manylinux_2_17_x86_64.whl \
     pypi/nvidia_cuda_crt-13.0.88-py3-none-manylinux2014_x86_64.manylinux_2_17_x86_64.whl \
     pypi/nvidia_nvvm-13.0.88-py3-none-manylinux2010_x86_64.manylinux_2_12_x86_64.whl \
     pypi/nvidia_cuda_cccl-13.0.85-py3-none-manylinux2014_x86_64.manylinux_2_17_x86_64.whl \
     pypi/ninja-1.13.0-py3-none-manylinux2014_x86_64.manylinux_2_17_x86_64.whl \
     /opt/slamrun-build/pypi-build/
COPY recipes/torch_cuda/requirements-build.txt /opt/slamrun-build/
RUN cd /opt/slamrun-build/pypi-build \
 && /opt/venv/bin/python -m pip install --no-index --no-cache-dir --find-links . \
      --require-hashes --no-deps -r /opt/slamrun-build/requirements-build.txt \
 && cd / && rm -rf /opt/slamrun-build/pypi-build
# DPV-SLAM's loop closure (DPVO with `loop_closure: true`): numba, pypose, einops and scipy, beside PyTorch, without
# their declared but unimported requirements (pypose's pytest)
COPY \
     pypi/numba-0.61.2-cp311-cp311-manylinux2014_x86_64.manylinux_2_17_x86_64.whl \
     pypi/llvmlite-0.44.0-cp311-cp311-manylinux_2_17_x86_64.manylinux2014_x86_64.whl \
     pypi/pypose-0.9.5-py3-none-any.whl \
     pypi/packaging-25.0-py3-none-any.whl \
     pypi/einops-0.8.2-py3-none-any.whl \
     pypi/scipy-1.15.3-cp311-cp311-manylinux_2_17_x86_64.manylinux2014_x86_64.whl \
     /opt/slamrun-build/pypi-loop-closure/
COPY recipes/torch_cuda/requirements-loop-closure.txt /opt/slamrun-build/
RUN cd /opt/slamrun-build/pypi-loop-closure \
 && /opt/venv/bin/python -m pip install --no-index --no-cache-dir --find-links . \
      --require-hashes --no-deps -r /opt/slamrun-build/requirements-loop-closure.txt \
 && cd / && rm -rf /opt/slamrun-build/pypi-loop-closure \
 && /opt/venv/bin/python -c "import numba, pypose, einops, scipy.spatial.transform; print('numba', numba.__version__)"

FROM torch-cuda AS torch-venv
RUN /opt/venv/bin/python -m pip uninstall -y --no-cache-dir \
      nvidia-cuda-nvcc nvidia-cuda-crt nvidia-nvvm nvidia-cuda-cccl ninja \
 && /opt/venv/bin/python -m pip uninstall -y --no-cache-dir triton

FROM debian:bookworm-slim AS torch-runtime
RUN apt-get update \
 && DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends python3 \
 && rm -rf /var/lib/apt/lists/*
COPY --from=torch-venv /opt/venv /opt/venv
ENV PATH=/opt/venv/bin:/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin \
    PYTHONPATH=/opt/slamrun PYTHONDONTWRITEBYTECODE=1 NUMBA_CACHE_DIR=/tmp/numba
# no compiler left: torch imports without it
RUN ! ls /opt/venv/lib/python3.11/site-packages/nvidia/cu13/bin/nvcc 2>/dev/null \
 && python3 -c "import torch, numpy, cv2" \
 && useradd --create-home --uid 1000 slam
