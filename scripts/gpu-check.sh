#!/usr/bin/env bash
# slamrun's GPU check, for a bare Linux machine with one NVIDIA GPU, PyTorch with CUDA, nvcc, no Docker, no network,
# the working tree copied there with .whl/ (`make gpu-wheels` fills it here) beside it. From the repository root:
#   bash scripts/gpu-check.sh [OUT] [--until-gpu]          (make gpu-check [OUT=DIR] [METHOD=droid_slam])
# It installs slamrun into $PYTHON's environment from the tree with the carried wheels, generates a synthetic room,
# compiles the GPU method $METHOD (dpvo; droid_slam, mast3r_slam) natively (all cores, this GPU's architecture only) with an
# untrained stand-in network, runs `slamrun campaign` with backend: local, forward and backward, and leaves in OUT
# (default $OUT, else ./gpu-check-out): results.csv, the runs' resource series (resources/), the runs' logs and run.json (runs/), the
# native build's record and log, the spec, the step logs (logs/) and a one-page summary.txt. Each step is printed
# with the time; the first failure stops it, naming the step and its log.
# --until-gpu: stop before the first step that needs the GPU machine (the compile), after the install, the
# synthetic room and the method's unpacked, patched tree (tests/test_gpu.py runs it so on a machine without a GPU).
# Settings (environment): METHOD (dpvo), PYTHON (python3), WHEELS (.whl), WORK (scratch folder, default
# $TMPDIR/slamrun-gpu-check), FRAMES (160), TRIALS (2 per direction), JOBS (all cores), ARCH (this GPU's compute
# capability), REUSE_BUILD (1: keep a native build already in WORK, for a second try on the same machine).
set -Eeuo pipefail

UNTIL_GPU=0
POSITIONAL=()
for arg in "$@"; do
  case $arg in
    --until-gpu) UNTIL_GPU=1 ;;
    -h|--help) sed -n '2,15p' "$0"; exit 0 ;;
    *) POSITIONAL+=("$arg") ;;
  esac
done
OUT_DIR=${POSITIONAL[0]:-${OUT:-gpu-check-out}}
PYTHON=${PYTHON:-python3}
WHEELS=${WHEELS:-.whl}
WORK=${WORK:-${TMPDIR:-/tmp}/slamrun-gpu-check}
FRAMES=${FRAMES:-160}
TRIALS=${TRIALS:-2}
JOBS=${JOBS:-$(nproc)}
METHOD=${METHOD:-dpvo}

mkdir -p "$OUT_DIR/logs"
OUT_DIR=$(cd "$OUT_DIR" && pwd)
WHEELS=$(cd "$WHEELS" 2>/dev/null && pwd || echo "$WHEELS")
T0=$(date +%s)
STEP="start"
STEP_LOG="$OUT_DIR/logs/gpu-check.log"
export XDG_CACHE_HOME="$WORK/xdg"  # slamrun's caches (the native build) in the scratch folder
export PYTHONUNBUFFERED=1

say() { printf '[%s +%4ss] %s\n' "$(date +%T)" "$(( $(date +%s) - T0 ))" "$*" | tee -a "$OUT_DIR/logs/gpu-check.log"; }
fail() { say "FAILED at step '$STEP': $*"; exit 1; }
trap 'say "FAILED at step '"'"'$STEP'"'"' (exit $?); its log: $STEP_LOG"; tail -n 25 "$STEP_LOG" 2>/dev/null || true' ERR
step() { STEP=$1; STEP_LOG="$OUT_DIR/logs/$1.log"; say "step $1: $2"; }
# run a step's command with its output in its log
logged() { "$@" >>"$STEP_LOG" 2>&1; }

step preflight "the machine: Python, the carried wheels and sources$([ $UNTIL_GPU = 1 ] || echo ', PyTorch with CUDA, the GPU, nvcc')"
logged "$PYTHON" -c 'import sys; print(sys.version); assert sys.version_info >= (3, 11), "slamrun needs Python 3.11+"' \
  || fail "$PYTHON is no Python 3.11+ (set PYTHON)"
ls "$WHEELS"/pydantic-*.whl "$WHEELS"/pydantic_core-*.whl "$WHEELS/eigen3-headers.tar.gz" \
  >>"$STEP_LOG" 2>&1 || fail "$WHEELS lacks the carried files: run 'make gpu-wheels' and carry .whl"
if [ $UNTIL_GPU = 0 ]; then
  logged "$PYTHON" -c 'import torch; print("torch", torch.__version__, "cuda", torch.version.cuda); assert torch.cuda.is_available(), "no CUDA device"; print(torch.cuda.get_device_name(0), torch.cuda.get_device_capability(0))' \
    || fail "PyTorch with a CUDA device is needed in $PYTHON (see $STEP_LOG)"
  logged nvidia-smi || fail "nvidia-smi does not answer"
  if [ "$METHOD" = mast3r_slam ]; then  # its image pins torchvision for its PyTorch; here the machine's own must serve
    logged "$PYTHON" -c 'import torchvision; print("torchvision", torchvision.__version__)' \
      || fail "MASt3R-SLAM needs torchvision, built with this machine's PyTorch, in $PYTHON (see $STEP_LOG)"
  fi
  logged nvcc --version || logged "${CUDA_HOME:-/usr/local/cuda}/bin/nvcc" --version || fail "no nvcc on PATH nor in \$CUDA_HOME"
  say "$(grep -m1 -E '^torch ' "$STEP_LOG" || true); $(nvidia-smi --query-gpu=name,driver_version,memory.total,compute_cap --format=csv,noheader 2>/dev/null | head -n1 || true)"
fi

step install "slamrun from the working tree into $PYTHON's environment, with the carried wheels (no index)"
logged "$PYTHON" -m pip install --no-index --no-deps $(ls "$WHEELS"/*.whl | grep -v /setuptools-)
if ! logged "$PYTHON" -c 'from setuptools.command import bdist_wheel' && ! logged "$PYTHON" -c 'import wheel'; then
  logged "$PYTHON" -m pip install --no-index --no-deps "$WHEELS"/setuptools-*.whl  # an editable install needs it
fi
logged "$PYTHON" -m pip install --no-index --no-deps --no-build-isolation -e .
SLAMRUN=("$PYTHON" -m slamrun.cli)
logged "${SLAMRUN[@]}" --version
logged "$PYTHON" -c "import pydantic, slamrun.engine.spec, slamrun.methods"
# the pinned archives $METHOD's native build takes, from its declaration (slamrun list-methods --json)
ARCHIVES=($("${SLAMRUN[@]}" list-methods --json | "$PYTHON" -c '
import json, sys
m = json.load(sys.stdin).get(sys.argv[1])
sys.exit(f"no method {sys.argv[1]!r}") if m is None else None
sys.exit(f"{sys.argv[1]} has no native build") if m["native_build"] is None else print(*m["native_build"]["archives"])
' "$METHOD" 2>>"$STEP_LOG")) || fail "METHOD=$METHOD: not a method with a native build (slamrun list-methods)"
ls "${ARCHIVES[@]/#/$WHEELS/sources/}" >>"$STEP_LOG" 2>&1 || fail "$WHEELS/sources lacks $METHOD's archives: run 'make gpu-wheels' and carry .whl"

step eigen "Eigen 3.4's headers from the carried archive"
if [ -f /usr/include/eigen3/Eigen/Core ]; then
  EIGEN=/usr/include/eigen3
else
  EIGEN="$WORK/eigen3"
  rm -rf "$EIGEN" && mkdir -p "$EIGEN"
  logged tar -xzf "$WHEELS/eigen3-headers.tar.gz" -C "$EIGEN"
fi
[ -f "$EIGEN/Eigen/Core" ] || fail "no Eigen/Core in $EIGEN"

step synth "a synthetic room: $FRAMES frames at 640x480 (slamrun synth)"
rm -rf "$WORK/data" && mkdir -p "$WORK/data"
logged "${SLAMRUN[@]}" synth --frames "$FRAMES" --size 640x480 --seed 0 --scene indoor "$WORK/data/room"

step unpack "$METHOD's pinned sources, checked, unpacked and patched (slamrun/methods/$METHOD/image/patches.py)"
rm -rf "$WORK/$METHOD-patched"
logged "${SLAMRUN[@]}" native-build "$METHOD" --unpack-only --sources "$WHEELS/sources" --into "$WORK/$METHOD-patched"
if [ $UNTIL_GPU = 1 ]; then
  say "stopped before the GPU steps (--until-gpu): work in $WORK"
  exit 0
fi

BUILD="$XDG_CACHE_HOME/slamrun/native/$METHOD"
if [ "${REUSE_BUILD:-0}" = 1 ] && [ -f "$BUILD/build.json" ]; then
  step build "reusing the native build in $BUILD (REUSE_BUILD=1)"
else
  step build "$METHOD's CUDA extensions with $JOBS jobs for this GPU${ARCH:+ (compute capability $ARCH)}, a stand-in network"
  logged "${SLAMRUN[@]}" native-build "$METHOD" --sources "$WHEELS/sources" --eigen "$EIGEN" --jobs "$JOBS" \
    --standin-model ${ARCH:+--arch "$ARCH"}
fi
# each compiled file's seconds (ninja's log: start ms, end ms, ..., target)
find "$BUILD" -name .ninja_log -exec awk -v OFS='\t' '!/^#/ {print ($2 - $1) / 1000 " s", $4}' {} + \
  >"$OUT_DIR/logs/compile-seconds.txt" 2>/dev/null || true
cp "$BUILD/build.json" "$OUT_DIR/native-build.json"
cp "$BUILD/build.log" "$OUT_DIR/logs/native-build-compiler.log"

# the method's published variants (its declaration: DPV-SLAM is dpvo with loop_closure: true), each one more method
# entry of the campaign, with the same stand-in network
variant_entries() {
  "${SLAMRUN[@]}" list-methods --json | "$PYTHON" -c '
import json, sys
for label, params in json.load(sys.stdin)[sys.argv[1]].get("variants", {}).items():
    print(f"  - name: {sys.argv[1]}\n    label: {label}-standin\n    params: {json.dumps(params)}")' "$METHOD"
}
VARIANTS=$(variant_entries | grep -c 'label:' || true)
step campaign "slamrun campaign: $METHOD and its $VARIANTS published variant(s) (stand-in network), backend local, forward and backward, $TRIALS trial(s) each"
SPEC="$OUT_DIR/gpu-check.yaml"
cat >"$SPEC" <<EOF
# written by scripts/gpu-check.sh
name: gpu-check
results: $WORK/results
cache: $WORK/cache/views
datasets:
  - name: synth
    path: $WORK/data
    sequences: [room]
methods:
  - name: $METHOD
    label: $METHOD-standin   # an untrained stand-in network: plumbing and resources only, accuracy meaningless
$(variant_entries)
directions: [forward, backward]
trials: $TRIALS
timeout_s: 300
lanes: 1
backend: local
measurement: exclusive
retries: 0
report: false
EOF
rm -rf "$WORK/results"
logged "${SLAMRUN[@]}" validate "$SPEC"
logged "${SLAMRUN[@]}" campaign "$SPEC" || say "the campaign ended non-zero (see $STEP_LOG); collecting what it left"

step collect "results.csv, the resource series, the runs' logs and the summary into $OUT_DIR"
cp "$WORK/results/results.csv" "$OUT_DIR/results.csv"
mkdir -p "$OUT_DIR/resources" "$OUT_DIR/runs"
while IFS= read -r run; do
  name=$(echo "${run#"$WORK/results/runs/"}" | tr '/' '_')
  cp "$run/resources.csv" "$OUT_DIR/resources/$name.csv" 2>/dev/null || true
  mkdir -p "$OUT_DIR/runs/$name"
  cp "$run"/log.txt "$run"/run.json "$run"/trajectory.txt "$OUT_DIR/runs/$name/" 2>/dev/null || true
done < <(find "$WORK/results/runs" -name run.json -printf '%h\n' | sort)
logged "$PYTHON" scripts/gpu_check_summary.py "$OUT_DIR" "$((  $(date +%s) - T0 ))"
cat "$OUT_DIR/summary.txt"
say "done in $(( $(date +%s) - T0 )) s: $OUT_DIR"
