#!/usr/bin/env bash
# Every GPU method's check in one go (DPVO, with DPV-SLAM; DROID-SLAM; MASt3R-SLAM), on the machine scripts/gpu-check.sh is written for. From the repository root:
#   bash scripts/gpu-check-all.sh [OUT]          (make gpu-check METHOD=all [OUT=DIR])
# The install, Eigen, the synthetic room and the unpack run once (gpu-check.sh --until-gpu, into OUT/setup); DPVO's
# and DROID-SLAM's native builds run side by side (each is a few nvcc jobs one after another: together they take
# about 300 s on 16 cores, against about 410 s one after the other); then each method's gpu-check.sh runs with
# REUSE_BUILD=1 into OUT/<method>, one after the other, so that no campaign shares the GPU. A failed build stops it,
# naming its log. The same settings as gpu-check.sh (PYTHON, WHEELS, WORK, FRAMES, TRIALS, JOBS, ARCH).
set -uo pipefail

OUT_DIR=${1:-${OUT:-gpu-check-out}}
export PYTHONUNBUFFERED=1 WORK=${WORK:-${TMPDIR:-/tmp}/slamrun-gpu-check}
export XDG_CACHE_HOME="$WORK/xdg"  # where gpu-check.sh looks for the builds to reuse
PYTHON=${PYTHON:-python3}
WHEELS=${WHEELS:-.whl}
T0=$(date +%s)
say() { printf '[%s +%4ss] %s\n' "$(date +%T)" "$(( $(date +%s) - T0 ))" "$*"; }

mkdir -p "$OUT_DIR" && OUT_DIR=$(cd "$OUT_DIR" && pwd)
say "setup once: install, Eigen, the synthetic room (gpu-check.sh --until-gpu)"
bash scripts/gpu-check.sh "$OUT_DIR/setup" --until-gpu || { say "FAILED in the setup: see $OUT_DIR/setup/logs"; exit 1; }
EIGEN=/usr/include/eigen3
[ -f "$EIGEN/Eigen/Core" ] || EIGEN="$WORK/eigen3"

# every method with a native build (its declaration), from slamrun list-methods --json
METHODS=($("$PYTHON" -m slamrun.cli list-methods --json | "$PYTHON" -c '
import json, sys
print(*(n for n, m in json.load(sys.stdin).items() if m["native_build"]))')) || { say "FAILED: slamrun list-methods"; exit 1; }
say "building ${METHODS[*]} side by side (logs: $OUT_DIR/build-<method>.log)"
pids=()
for m in "${METHODS[@]}"; do
  (
    t=$(date +%s)
    "$PYTHON" -m slamrun.cli native-build "$m" --sources "$WHEELS/sources" --eigen "$EIGEN" --jobs "${JOBS:-$(nproc)}" \
      --standin-model ${ARCH:+--arch "$ARCH"} >"$OUT_DIR/build-$m.log" 2>&1
    rc=$?
    say "build $m: exit $rc after $(( $(date +%s) - t )) s"
    exit $rc
  ) &
  pids+=($!)
done
failed=()
for i in "${!METHODS[@]}"; do
  wait "${pids[$i]}" || failed+=("${METHODS[$i]}")
done
if [ ${#failed[@]} -gt 0 ]; then
  for m in "${failed[@]}"; do
    say "FAILED: the build of $m; its log $OUT_DIR/build-$m.log ends:"
    tail -n 5 "$OUT_DIR/build-$m.log"
  done
  exit 1
fi

rc=0
for m in "${METHODS[@]}"; do
  REUSE_BUILD=1 METHOD=$m bash scripts/gpu-check.sh "$OUT_DIR/$m" || { say "FAILED: the check of $m"; rc=1; }
done
say "done in $(( $(date +%s) - T0 )) s: each method's summary.txt in $OUT_DIR/<method>"
exit $rc
