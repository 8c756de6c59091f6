#!/usr/bin/env bash
# What scripts/gpu-check.sh carries to a GPU machine without network, into one ignored folder (default .whl/):
# the wheels slamrun needs that such a machine lacks (Python 3.12, manylinux x86_64; PyTorch, NumPy, SciPy, pandas,
# pyarrow, OpenCV, matplotlib, psutil, rich, PyYAML and requests are there already), ninja (PyTorch's parallel
# extension build), Eigen 3.4's headers (the extensions include them) and the GPU methods' pinned source archives
# (DPVO; DROID-SLAM with its lietorch submodule; MASt3R-SLAM, with lietorch too).
# usage: scripts/gpu-wheels.sh [DIR] [PYTHON_VERSION]      (make gpu-wheels [WHEELS=DIR] [GPU_PY=3.12])
set -euo pipefail
DIR=${1:-.whl}
PYVER=${2:-3.12}
PY=${PY:-python3}
SOURCES=${SOURCES:-../shared/upstream}
# the archives of every method with a native build, from their declarations (slamrun list-methods --json): slamrun
# is run by SLAMRUN_PY (default PY), a Python that has it installed
ARCHIVES=($("${SLAMRUN_PY:-$PY}" -m slamrun.cli list-methods --json | "${SLAMRUN_PY:-$PY}" -c '
import json, sys
print(*sorted({a for m in json.load(sys.stdin).values() if m["native_build"] for a in m["native_build"]["archives"]}))'))
[ ${#ARCHIVES[@]} -gt 0 ] || { echo "gpu-wheels: no archives: is slamrun installed in ${SLAMRUN_PY:-$PY}? (make gpu-wheels)" >&2; exit 1; }
# pinned as tested with slamrun (pyproject: pydantic>=2.5); typing-extensions: pydantic 2.14 needs >= 4.14.1;
# setuptools: installed there only when its own cannot build an editable wheel (older than 70.1, no `wheel`)
WHEELS=(pydantic==2.14.4 pydantic-core==2.50.5 annotated-types==0.8.0 typing-inspection==0.4.5
        typing-extensions==4.16.0 ninja==1.13.2 setuptools==80.9.0)
# MASt3R-SLAM's modules import these beside PyTorch (its image's pins, slamrun/images/sources.py MAST3R_SLAM): faiss-cpu
# (its retrieval index), natsort and plyfile; torchvision must be the one built with the machine's PyTorch (its own),
# and Pillow, tqdm and PyYAML are there with it
WHEELS+=(faiss-cpu==1.15.1 natsort==8.4.0 plyfile==1.1.5)

mkdir -p "$DIR"
rm -f "$DIR"/*.whl
"$PY" -m pip download --quiet --no-deps --only-binary=:all: --python-version "$PYVER" --implementation cp \
  --platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 -d "$DIR" \
  "${WHEELS[@]}"

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

# the pinned archives (checked again by slamrun native-build)
mkdir -p "$DIR/sources"
for archive in "${ARCHIVES[@]}"; do
  if [ ! -s "$DIR/sources/$archive" ]; then
    [ -s "$SOURCES/$archive" ] || { echo "gpu-wheels: $SOURCES/$archive not found (give SOURCES=DIR)" >&2; exit 1; }
    cp "$SOURCES/$archive" "$DIR/sources/"
  fi
done
(cd "$DIR" && sha256sum ./*.whl eigen3-headers.tar.gz "${ARCHIVES[@]/#/sources/}" > SHA256SUMS)
du -sh "$DIR"
