# Python 2.7 (the image's): an untrained stand-in for mask_rcnn_coco.h5, made with DynaSLAM's own Mask R-CNN code
# (src/python/model.py, coco.CocoConfig: ResNet-101, 81 classes) so it has exactly the layers and shapes the
# real weights have. Weights: Keras' initialisers under fixed seeds; the classifier head's background logit is
# raised so every region is background: the stand-in never detects (never masks) anything, DynaSLAM runs as it
# does on a scene without people or cars, and no degenerate random box reaches the mask resizer.
# Plumbing tests only (the image's label and mask_rcnn_coco.h5.txt say so), never results.
# usage (from src/python): python2.7 standin_model.py DEST
from __future__ import print_function

import sys

import numpy as np
import tensorflow as tf

sys.path.insert(0, ".")  # DynaSLAM's src/python: the working directory
np.random.seed(0)
tf.set_random_seed(0)

import coco  # noqa: E402
import model as modellib  # noqa: E402


class StandinConfig(coco.CocoConfig):
    GPU_COUNT = 1
    IMAGES_PER_GPU = 1


net = modellib.MaskRCNN(mode="inference", model_dir="/tmp/mask-rcnn-logs", config=StandinConfig())
logits = net.keras_model.get_layer("mrcnn_class_logits")
weights, bias = logits.get_weights()
assert bias.shape == (81,), bias.shape
bias[0] = 1000.0  # background, always
logits.set_weights([weights, bias])
net.keras_model.save_weights(sys.argv[1])
print("standin_model: wrote", sys.argv[1])
