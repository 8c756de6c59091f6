"""SVO (uzh-rpg/rpg_svo @ d616106, with rpg_vikit, fast and Sophus @ a621ff) without ROS on Debian 12: the svo
library and vikit_common built with their own USE_ROS switches off, SVO's parameters read from a flat file as
the ROS node reads them (-DSLAMRUN_PARAMS, a ROS-free vikit/params_helper.h in slamrun/methods/recipes/common/svo-include), and
slamrun's offline driver (svo_offline.cpp) instead of the ROS benchmark node.

- Sophus @ a621ff, sophus/so2.cpp: `unit_complex_.real() = 1.;` assigns to an rvalue since C++11 (gcc >= 5):
  the complex number is set whole.
- fast, CMakeLists.txt: no test program (BUILD_TEST TRUE builds fast_test against OpenCV's highgui); -std=c++11
  (gcc 12 defaults to C++17, where fast's `register` variables are errors under its -Werror).
- rpg_vikit/vikit_common: USE_ROS off; OpenCV 4 constants; the debug windows of img_align.cpp dropped (never
  shown headless, and they would link OpenCV's GUI); ATAN (FOV) camera: the distortion factors at the image
  centre are the model's limits (upstream returns 1 below a radius of 0.01 / 0.001, a jump of
  s / (2 tan(s/2)) - 1, -6 % for s = 0.8, within a few pixels of the principal point).
- rpg_svo/svo: USE_ROS off, our include folder first and SLAMRUN_PARAMS (config.cpp reads its parameters through
  vk::getParam, with the ROS node's defaults, instead of the compiled-in non-ROS ones); Boost >= 1.73 bind
  placeholders in global.h; the debug window of sparse_img_align.cpp dropped (its only OpenCV C constant); the driver
  target svo_offline; the tests are not configured (they need data that is not in the tree).
usage: patches.py SVO_ROOT VIKIT_ROOT FAST_ROOT SOPHUS_ROOT
"""
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "common"))
sys.path.insert(1, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "recipes", "common"))  # in slamrun's tree
from families import drop_after, fast_cxx11, sophus_cxx11, svo_without_ros, vikit_common_without_ros  # noqa: E402
from patchlib import patch, sub  # noqa: E402

DEBUG_WINDOW = r"\n(\s*)cv::namedWindow\(\"residuals\", CV_WINDOW_AUTOSIZE\);\n\s*cv::imshow\([^;]*;\n\s*cv::waitKey\(0\);"
NO_WINDOW = r"\n\1// slamrun: no debug window (headless build without OpenCV's GUI)"


def vikit(root):
    sub(root, "vikit_common/src/img_align.cpp", DEBUG_WINDOW, NO_WINDOW, min_count=2)
    vikit_common_without_ros(root)
    # the FOV model's factors at r -> 0 (atan(r t)/(s r) -> t/s, tan(r s)/(t r) -> s/t, t = 2 tan(s/2))
    header = "vikit_common/include/vikit/atan_camera.h"
    patch(root, header, "replace",
          "    if(r < 0.001 || s_ == 0.0)\n      return 1.0;\n",
          "    if(s_ == 0.0)\n      return 1.0;\n"
          "    if(r < 0.001)  // slamrun: the limit, not 1\n      return s_inv_ * tans_;\n")
    patch(root, "vikit_common/src/atan_camera.cpp", "replace",
          "  else\n    d_factor = 1.0;\n",
          "  else  // slamrun: the limit at the centre, not 1\n    d_factor = (s_ == 0.0) ? 1.0 : s_ * tans_inv_;\n")


def svo(root):
    # the tests need data that is not in the tree; the driver replaces them
    drop_after(root, "svo/CMakeLists.txt",
               "################################################################################\n# TESTS")
    svo_without_ros(root, "svo", "svo_offline")
    sub(root, "svo/src/sparse_img_align.cpp", DEBUG_WINDOW, NO_WINDOW)  # its only OpenCV C constant


if __name__ == "__main__":
    if len(sys.argv) != 5:
        sys.exit("usage: patches.py SVO_ROOT VIKIT_ROOT FAST_ROOT SOPHUS_ROOT")
    svo_root, vikit_root, fast_root, sophus_root = sys.argv[1:]
    sophus_cxx11(sophus_root)
    fast_cxx11(fast_root)
    vikit(vikit_root)
    svo(svo_root)
