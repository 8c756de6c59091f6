#!/bin/sh
# The frozen MonoDepth graph an image runs (CNN-DSO's cnn=, CNN-SVO's svo/cnn_model), by the build's choice:
#   given    inputs/weights/model_city2kitti.pb of the build context (`slamrun images --weights
#            model_city2kitti.pb=FILE`, or a URL + SHA-256 the runner fetched there); optional SHA-256 check
#   standin  a graph with monodepth-cpp's interface and UNTRAINED weights, made now (make_standin_model):
#            plumbing tests only, never results
# Either way the graph is loaded and run once (check_model) so a wrong file fails the build, not a run.
# usage: model.sh CHOICE INPUTS DEST SHA256 MONODEPTH_BUILD
set -eu
choice=$1; inputs=$2; dest=$3; sum=$4; bin=$5
mkdir -p "$(dirname "$dest")"
case "$choice" in
  given)
    src="$inputs/weights/model_city2kitti.pb"
    if [ ! -s "$src" ]; then
      cat >&2 <<MSG
model: the frozen MonoDepth graph model_city2kitti.pb is missing (inputs/weights/model_city2kitti.pb).
  Its authors publish it: monodepth-cpp's model/README.md links the converted graph (a Google Drive file) and
  freeze_graph/README.md the VGG (city2kitti) and ResNet50 graphs; MonoDepth's own site serves only .zip
  checkpoints, which freeze_graph/freeze_graph.py (TensorFlow 1.x Python) turns into a .pb.
  Give it with: slamrun images --weights model_city2kitti.pb=FILE   (or build with MONODEPTH_MODEL=standin
  for an untrained stand-in that only tests the plumbing).
MSG
      exit 1
    fi
    if [ -n "$sum" ]; then
      actual=$(sha256sum "$src" | cut -d' ' -f1)
      [ "$actual" = "$sum" ] || { echo "model: $src has sha256 $actual, expected $sum" >&2; exit 1; }
    fi
    cp "$src" "$dest"
    echo "given: model_city2kitti.pb sha256 $(sha256sum "$dest" | cut -d' ' -f1)" > "$dest.txt" ;;
  standin)
    "$bin/make_standin_model" "$dest"
    echo "standin: untrained graph from make_standin_model (constant depth 10 m); NOT MonoDepth" > "$dest.txt" ;;
  *)
    echo "model: MONODEPTH_MODEL must be given or standin (got '$choice')" >&2; exit 1 ;;
esac
"$bin/check_model" "$dest" 640 480
