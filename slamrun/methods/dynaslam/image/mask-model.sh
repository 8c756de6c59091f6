#!/bin/sh
# Mask R-CNN's weights in DynaSLAM's tree (src/python/mask_rcnn_coco.h5), by the build's choice:
#   given    inputs/weights/mask_rcnn_coco.h5 of the build context (`slamrun images --weights
#            mask_rcnn_coco.h5=FILE`, or a URL + SHA-256 the runner fetched there); optional SHA-256 check
#   standin  made now by standin_model.py with DynaSLAM's own Mask R-CNN code: the same architecture and 81
#            classes, random weights from a fixed seed, every region classified as background (no dynamic
#            object is ever masked): plumbing tests only, never results
# Either way DynaSLAM's MaskRCNN.Mask loads the file and segments one frame, so a wrong file fails the build.
# usage: mask-model.sh CHOICE INPUTS DYNASLAM_ROOT SHA256
set -eu
choice=$1; inputs=$2; root=$3; sum=${4:-}
here=$(cd "$(dirname "$0")" && pwd)
dest=$root/src/python/mask_rcnn_coco.h5
case "$choice" in
  given)
    src=$inputs/weights/mask_rcnn_coco.h5
    if [ ! -s "$src" ]; then
      cat >&2 <<MSG
mask-model: mask_rcnn_coco.h5 is missing (inputs/weights/mask_rcnn_coco.h5).
  Its authors publish it as an asset of the matterport/Mask_RCNN GitHub release v2.0 (mask_rcnn_coco.h5, 246 MB).
  Give it with: slamrun images --weights mask_rcnn_coco.h5=FILE (or =URL#sha256=HEX), or build with
  --standin-model (MASK_RCNN_MODEL=standin) for an untrained stand-in that only tests the plumbing.
MSG
      exit 1
    fi
    if [ -n "$sum" ]; then
      actual=$(sha256sum "$src" | cut -d' ' -f1)
      [ "$actual" = "$sum" ] || { echo "mask-model: $src has sha256 $actual, expected $sum" >&2; exit 1; }
    fi
    cp "$src" "$dest"
    echo "given: mask_rcnn_coco.h5 sha256 $(sha256sum "$dest" | cut -d' ' -f1)" > "$dest.txt" ;;
  standin)
    (cd "$root/src/python" && python2.7 "$here/standin_model.py" "$dest")
    echo "standin: untrained Mask R-CNN (DynaSLAM's model.py, 81 classes, seed 0, every region background);" \
      "NOT the COCO weights; sha256 $(sha256sum "$dest" | cut -d' ' -f1)" > "$dest.txt" ;;
  *)
    echo "mask-model: MASK_RCNN_MODEL must be given or standin (got '$choice')" >&2; exit 1 ;;
esac
# DynaSLAM's own loader, from the tree's root as mono_tum runs it, on the CPU
cd "$root" && MPLBACKEND=Agg CUDA_VISIBLE_DEVICES= python2.7 "$here/check_mask_rcnn.py"
cat "$dest.txt"
