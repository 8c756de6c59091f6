#!/usr/bin/env bash
# The image's network, /opt/droid_slam/weights/droid.pth, and its record /opt/droid_slam/build.json (what
# slamrun/methods/droid_slam/process.py reads: the tree, the weights file and what it is).
# MODEL: given = inputs/weights/droid.pth (`slamrun images --weights droid.pth=FILE` or =URL#sha256=HEX); standin = an
# untrained stand-in from a fixed seed (slamrun/methods/droid_slam/image/standin_model.py, as `slamrun native-build droid_slam
# --standin-model`; plumbing only, accuracy meaningless); anything else: the build stops naming the file and where it
# is published.
# usage: network.sh MODEL INPUTS BUILD_DIR ARCH_LIST STANDIN_PY
set -euo pipefail
model=$1 inputs=$2 build=$3 arch=$4 standin=$5
py=/opt/venv/bin/python
tree=$(cd "$build" && ls -d DROID-SLAM-*)
mkdir -p "$build/weights"
out=$build/weights/droid.pth
case "$model" in
  given)
    [ -s "$inputs/weights/droid.pth" ] || { echo "network: inputs/weights/droid.pth missing" >&2; exit 1; }
    cp "$inputs/weights/droid.pth" "$out"
    note="droid.pth: given, sha256 $(sha256sum "$out" | cut -d' ' -f1)" ;;
  standin)
    seed=0 flow_px=8
    gain=$("$py" "$standin" "$build/$tree" "$out" "$seed" "$flow_px" | tail -1)
    note="untrained stand-in with droid.pth's interface (random init, torch seed $seed, $gain for a mean flow of ${flow_px} px, sha256 $(sha256sum "$out" | cut -d' ' -f1)): plumbing only, NOT the trained network, accuracy meaningless" ;;
  *)
    echo "network: DROID-SLAM needs droid.pth: give it with slamrun images --weights droid.pth=FILE (or" \
      "=URL#sha256=HEX), or --standin-model for an untrained stand-in (plumbing only). It is published by" \
      "DROID-SLAM's tools/download_model.sh (a Google Drive file)" >&2
    exit 1 ;;
esac
TREE=$tree ARCH=$arch NOTE=$note "$py" - "$build/build.json" <<'PY'
import json, os, sys, torch
record = {"method": "droid_slam", "image": True, "tree": os.environ["TREE"], "torch": torch.__version__,
          "cuda": torch.version.cuda, "arch": os.environ["ARCH"], "weights_file": "weights/droid.pth",
          "weights": os.environ["NOTE"]}
open(sys.argv[1], "w").write(json.dumps(record, indent=1) + "\n")
print(json.dumps(record))
PY
