# Python 2.7 (the image's), run from DynaSLAM's root as mono_tum runs it: DynaSLAM's MaskRCNN.Mask loads
# src/python/mask_rcnn_coco.h5 and segments one 640x480 frame on the CPU. Prints the seconds it took.
# usage: cd DYNASLAM_ROOT && python2.7 check_mask_rcnn.py
from __future__ import print_function

import sys
import time

import numpy as np

sys.path.insert(0, "src/python")
import MaskRCNN  # noqa: E402

t0 = time.time()
net = MaskRCNN.Mask()
t1 = time.time()
frame = (np.random.RandomState(0).rand(480, 640, 3) * 255).astype(np.uint8)
mask = net.GetDynSeg(frame)
t2 = time.time()
assert mask.shape == (480, 640), mask.shape
print("check_mask_rcnn: Mask R-CNN loads in %.1f s, segments a 640x480 frame in %.1f s (%d masked pixels)"
      % (t1 - t0, t2 - t1, int(mask.sum())))
