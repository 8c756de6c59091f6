#!/usr/bin/env bash
# The image's checkpoints, /opt/mast3r_slam/weights/ (the MASt3R network, the retrieval head and its codebook, under
# their published names), and its record /opt/mast3r_slam/build.json (what slamrun/methods/mast3r_slam/process.py reads:
# the tree, the network's file and what it is).
# MODEL: given = the three files in inputs/weights/ (`slamrun images --weights NAME=FILE` for each); standin = untrained
# stand-ins from a fixed seed (slamrun/methods/mast3r_slam/image/standin_model.py, as `slamrun native-build mast3r_slam
# --standin-model`; plumbing only, accuracy meaningless); anything else: the build stops naming the files and where they
# are published.
# usage: network.sh MODEL INPUTS BUILD_DIR ARCH_LIST STANDIN_PY
set -euo pipefail
model=$1 inputs=$2 build=$3 arch=$4 standin=$5
py=/opt/venv/bin/python
tree=$(cd "$build" && ls -d MASt3R-SLAM-*)
stem=MASt3R_ViTLarge_BaseDecoder_512_catmlpdpt_metric
files=("$stem.pth" "${stem}_retrieval_trainingfree.pth" "${stem}_retrieval_codebook.pkl")
mkdir -p "$build/weights"
case "$model" in
  given)
    note=""
    for f in "${files[@]}"; do
      [ -s "$inputs/weights/$f" ] || { echo "network: inputs/weights/$f missing" >&2; exit 1; }
      cp "$inputs/weights/$f" "$build/weights/$f"
      note="$note${note:+; }$f: given, sha256 $(sha256sum "$build/weights/$f" | cut -d' ' -f1)"
    done ;;
  standin)
    seed=0
    made=$("$py" "$standin" "$build/$tree" "$build/weights/${files[0]}" "$seed" | tail -1)
    note="untrained stand-ins with MASt3R-SLAM's checkpoints' interface (random init, torch seed $seed, $made; sha256"
    for f in "${files[@]}"; do note="$note $f $(sha256sum "$build/weights/$f" | cut -d' ' -f1)"; done
    note="$note): plumbing only, NOT the trained network, accuracy meaningless" ;;
  *)
    echo "network: MASt3R-SLAM needs ${files[*]}: give each with slamrun images --weights NAME=FILE (or" \
      "=URL#sha256=HEX), or --standin-model for untrained stand-ins (plumbing only). They are published on" \
      "download.europe.naverlabs.com (MASt3R-SLAM's README, checkpoints/)" >&2
    exit 1 ;;
esac
TREE=$tree ARCH=$arch NOTE=$note FILE="weights/${files[0]}" "$py" - "$build/build.json" <<'PY'
import json, os, sys, torch
record = {"method": "mast3r_slam", "image": True, "tree": os.environ["TREE"], "torch": torch.__version__,
          "cuda": torch.version.cuda, "arch": os.environ["ARCH"], "weights_file": os.environ["FILE"],
          "weights": os.environ["NOTE"]}
open(sys.argv[1], "w").write(json.dumps(record, indent=1) + "\n")
print(json.dumps(record))
PY
