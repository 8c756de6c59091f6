#!/usr/bin/env bash
# The image's network, /opt/dpvo/weights/dpvo.pth, and its record /opt/dpvo/build.json (what
# slamrun/methods/dpvo/process.py reads: the tree, the weights file and what it is).
# MODEL: given = inputs/weights/dpvo.pth (`slamrun images --weights dpvo.pth=FILE` or =URL#sha256=HEX); standin = an
# untrained stand-in from a fixed seed (slamrun/methods/dpvo/image/standin_model.py, as `slamrun native-build dpvo --standin-model`;
# plumbing only, accuracy meaningless); anything else: the build stops naming the file and where it is published.
# usage: network.sh MODEL INPUTS BUILD_DIR ARCH_LIST STANDIN_PY
set -euo pipefail
model=$1 inputs=$2 build=$3 arch=$4 standin=$5
py=/opt/venv/bin/python
tree=$(cd "$build" && ls -d DPVO-*)
mkdir -p "$build/weights"
out=$build/weights/dpvo.pth
case "$model" in
  given)
    [ -s "$inputs/weights/dpvo.pth" ] || { echo "network: inputs/weights/dpvo.pth missing" >&2; exit 1; }
    cp "$inputs/weights/dpvo.pth" "$out"
    note="dpvo.pth: given, sha256 $(sha256sum "$out" | cut -d' ' -f1)" ;;
  standin)
    seed=0 gain=16
    "$py" "$standin" "$build/$tree" "$out" "$seed" "$gain"
    note="untrained stand-in with dpvo.pth's interface (random init, torch seed $seed, flow head x$gain, sha256 $(sha256sum "$out" | cut -d' ' -f1)): plumbing only, NOT the trained network, accuracy meaningless" ;;
  *)
    echo "network: DPVO needs dpvo.pth: give it with slamrun images --weights dpvo.pth=FILE (or =URL#sha256=HEX), or" \
      "--standin-model for an untrained stand-in (plumbing only). It is published in DPVO's" \
      "download_models_and_data.sh (models.zip)" >&2
    exit 1 ;;
esac
TREE=$tree ARCH=$arch NOTE=$note "$py" - "$build/build.json" <<'PY'
import json, os, sys, torch
record = {"method": "dpvo", "image": True, "tree": os.environ["TREE"], "torch": torch.__version__,
          "cuda": torch.version.cuda, "arch": os.environ["ARCH"], "weights_file": "weights/dpvo.pth",
          "weights": os.environ["NOTE"]}
open(sys.argv[1], "w").write(json.dumps(record, indent=1) + "\n")
print(json.dumps(record))
PY
