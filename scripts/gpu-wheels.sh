#!/usr/bin/env bash
# What scripts/gpu-check.sh carries to a GPU machine without network, into one ignored folder (default .whl/):
# the wheels slamrun needs that such a machine lacks (Python 3.12, manylinux x86_64; PyTorch, NumPy, SciPy, pandas,
# pyarrow, OpenCV, matplotlib, psutil, rich, PyYAML and requests are there already), ninja (PyTorch's parallel
# extension build), Eigen 3.4's headers (DPVO's extensions include them) and DPVO's pinned source archive.
# usage: scripts/gpu-wheels.sh [DIR] [PYTHON_VERSION]      (make gpu-wheels [WHEELS=DIR] [GPU_PY=3.12])
set -euo pipefail
DIR=${1:-.whl}
PYVER=${2:-3.12}
PY=${PY:-python3}
SOURCES=${SOURCES:-../shared/upstream}
DPVO=DPVO-859bbbfdac6c6185f345003b3c473901fcd13ace.tar.gz
# pinned as tested with slamrun (pyproject: pydantic>=2.5); typing-extensions: pydantic 2.14 needs >= 4.14.1;
# setuptools: installed there only when its own cannot build an editable wheel (older than 70.1, no `wheel`)
WHEELS=(pydantic==2.14.4 pydantic-core==2.50.5 annotated-types==0.8.0 typing-inspection==0.4.5
        typing-extensions==4.16.0 ninja==1.13.2 setuptools==80.9.0)

mkdir -p "$DIR"
rm -f "$DIR"/*.whl
"$PY" -m pip download --quiet --no-deps --only-binary=:all: --python-version "$PYVER" --implementation cp \
  --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 -d "$DIR" "${WHEELS[@]}"

# Eigen's headers: the system's (Debian's libeigen3-dev), else the package itself, unpacked here
if [ ! -s "$DIR/eigen3-headers.tar.gz" ]; then
  if [ -f /usr/include/eigen3/Eigen/Core ]; then
    tar -czf "$DIR/eigen3-headers.tar.gz" -C /usr/include/eigen3 Eigen signature_of_eigen3_matrix_library
  else
    tmp=$(mktemp -d)
    (cd "$tmp" && apt-get download libeigen3-dev >/dev/null 2>&1) \
      || { echo "gpu-wheels: no Eigen: apt-get download libeigen3-dev failed (install libeigen3-dev)" >&2; exit 1; }
    dpkg-deb -x "$tmp"/libeigen3-dev_*.deb "$tmp/x"
    tar -czf "$DIR/eigen3-headers.tar.gz" -C "$tmp/x/usr/include/eigen3" Eigen signature_of_eigen3_matrix_library
    rm -rf "$tmp"
  fi
fi

# DPVO's pinned archive (checked again by slamrun native-build)
if [ ! -s "$DIR/sources/$DPVO" ]; then
  mkdir -p "$DIR/sources"
  [ -s "$SOURCES/$DPVO" ] || { echo "gpu-wheels: $SOURCES/$DPVO not found (give SOURCES=DIR)" >&2; exit 1; }
  cp "$SOURCES/$DPVO" "$DIR/sources/"
fi
(cd "$DIR" && sha256sum ./*.whl eigen3-headers.tar.gz "sources/$DPVO" > SHA256SUMS)
du -sh "$DIR"
