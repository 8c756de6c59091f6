"""CNN-SVO @ d5591ea without ROS on Debian 12: its svo library (SVO + CNN depth, FrameHandlerOnline) and its
vendored rpg_vikit/vikit_common built with their own USE_ROS switches off, MonoDepth through monodepth-cpp on
the tensorflow-cpu wheel's TF 2 C++, and slamrun's offline driver (cnn_svo_offline.cpp) instead of the ROS node.

- rpg_svo/svo/CMakeLists.txt (~4-9, ~137-151): USE_ROS off; the ${HOME}/catkin_ws/... monodepth paths and
  ${HOME}/tensorflow/local/lib/libtensorflow_all.so become -DMONODEPTH_ROOT / -DTENSORFLOW_ROOT; our include
  folder (-DSLAMRUN_INCLUDE_DIR, a ROS-free vikit/params_helper.h) comes first; the driver is added.
- rpg_svo/svo/src/config.cpp: SVO's parameters are read through getParam also without ROS (SLAMRUN_PARAMS).
- rpg_svo/svo/CMakeLists.txt (~118): g2o's include dir (commented out upstream); include/svo/global.h: Boost's
  bind placeholders (Boost >= 1.73).
- rpg_vikit/vikit_common/CMakeLists.txt: USE_ROS off. OpenCV 4 constants in both.
- Sophus, fast, vikit_common and the svo library's ROS switch: the families SVO's recipe uses too
  (slamrun/methods/recipes/common/families.py).
usage: patches.py CNN_SVO_ROOT SOPHUS_ROOT FAST_ROOT
"""
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "common"))
sys.path.insert(1, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "recipes", "common"))  # in slamrun's tree
from families import fast_cxx11, sophus_cxx11, svo_without_ros, vikit_common_without_ros  # noqa: E402
from patchlib import opencv4, patch  # noqa: E402

SVO = "rpg_svo/svo"
VIKIT = "rpg_vikit/vikit_common"


def svo(root):
    cm = os.path.join(SVO, "CMakeLists.txt")
    patch(root, cm, "replace", "set(monodepth_INCLUDE_DIRS ${HOME}/catkin_ws/src/CNN-VO/monodepth/install/include)",
          "set(monodepth_INCLUDE_DIRS ${MONODEPTH_ROOT}/include)  # slamrun")
    patch(root, cm, "replace",
          "TARGET_LINK_LIBRARIES(svo ${HOME}/catkin_ws/src/CNN-VO/monodepth/install/lib/libmonodepth_static.a)\n"
          "  TARGET_LINK_LIBRARIES(svo ${HOME}/tensorflow/local/lib/libtensorflow_all.so)",
          "TARGET_LINK_LIBRARIES(svo ${MONODEPTH_ROOT}/build/libmonodepth_static.a)  # slamrun\n"
          "  TARGET_LINK_LIBRARIES(svo ${TENSORFLOW_ROOT}/libtensorflow_cc.so.2 "
          "${TENSORFLOW_ROOT}/libtensorflow_framework.so.2)")
    with open(os.path.join(root, cm)) as f:
        left = [w for w in f.read().split() if "${HOME}" in w or w.startswith("/home/")]
    if left:
        sys.exit("patch: %s still holds personal paths: %s" % (cm, left[:5]))
    # its g2o include line is commented out (upstream relied on ROS Kinetic's /opt/ros/kinetic/include)
    patch(root, cm, "replace", "    #${G2O_INCLUDE_DIR}\n", "    ${G2O_INCLUDE_DIR}  # slamrun\n")
    svo_without_ros(root, SVO, "cnn_svo_offline")
    opencv4(root, [os.path.join(SVO, "src")])


if __name__ == "__main__":
    if len(sys.argv) != 4:
        sys.exit("usage: patches.py CNN_SVO_ROOT SOPHUS_ROOT FAST_ROOT")
    cnn_svo_root, sophus_root, fast_root = sys.argv[1:]
    sophus_cxx11(sophus_root)
    fast_cxx11(fast_root)
    vikit_common_without_ros(cnn_svo_root, VIKIT)
    svo(cnn_svo_root)
