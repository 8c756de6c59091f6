#!/bin/sh
# Mask R-CNN's COCO weights, as a file given to the build (`slamrun images --weights mask_rcnn_coco.h5=FILE`,
# or a URL + SHA-256 the runner fetched into inputs/weights/), checked against SHA256 when one is given.
# usage: mask-weights.sh INPUTS DEST [SHA256]
set -eu
src=$1/weights/mask_rcnn_coco.h5; dest=$2; sum=${3:-}
if [ ! -s "$src" ]; then
  cat >&2 <<MSG
mask-weights: mask_rcnn_coco.h5 is missing (inputs/weights/mask_rcnn_coco.h5).
  Its authors publish it as an asset of the matterport/Mask_RCNN GitHub release v2.0 (mask_rcnn_coco.h5, 246 MB).
  Give it with: slamrun images --weights mask_rcnn_coco.h5=FILE
MSG
  exit 1
fi
if [ -n "$sum" ]; then
  actual=$(sha256sum "$src" | cut -d' ' -f1)
  [ "$actual" = "$sum" ] || { echo "mask-weights: $src has sha256 $actual, expected $sum" >&2; exit 1; }
fi
cp "$src" "$dest"
echo "mask-weights: $dest sha256 $(sha256sum "$dest" | cut -d' ' -f1)"
