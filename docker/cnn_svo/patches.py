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
- Sophus @ a621ff: the one-line fix for gcc >= 5 (as docker/svo); fast: -std=c++11 (gcc 12's default C++17
  rejects its `register` variables, and it builds with -Werror).
usage: patches.py CNN_SVO_ROOT SOPHUS_ROOT FAST_ROOT
"""
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "common"))
from patchlib import append_line, opencv4, patch, sub  # noqa: E402

SVO = "rpg_svo/svo"
VIKIT = "rpg_vikit/vikit_common"


def sophus(root):
    patch(root, "sophus/so2.cpp", "replace", "unit_complex_.real() = 1.;\n  unit_complex_.imag() = 0.;",
          "unit_complex_ = std::complex<double>(1, 0);")


def fast(root):
    # gcc 12 defaults to C++17, where fast's `register` variables are errors under its -Werror
    patch(root, "CMakeLists.txt", "replace", 'SET(CMAKE_CXX_FLAGS "-Wall -Werror ',
          'SET(CMAKE_CXX_FLAGS "-std=c++11 -Wall -Werror ')


def vikit_common(root):
    path = os.path.join(VIKIT, "CMakeLists.txt")
    patch(root, path, "replace", "SET(USE_ROS TRUE)", "SET(USE_ROS FALSE)  # slamrun")
    opencv4(root, [os.path.join(VIKIT, "src")])
    sub(root, os.path.join(VIKIT, "src/homography.cpp"), r"\bCV_RANSAC\b", "cv::RANSAC")


def svo(root):
    cm = os.path.join(SVO, "CMakeLists.txt")
    patch(root, cm, "replace", "SET(USE_ROS TRUE)", "SET(USE_ROS FALSE)  # slamrun")
    patch(root, cm, "replace", "ELSE()\n  INCLUDE_DIRECTORIES(${vikit_common_INCLUDE_DIRS})\n",
          "ELSE()\n"
          "  # slamrun: a ROS-free vikit/params_helper.h, before anything else\n"
          "  INCLUDE_DIRECTORIES(BEFORE ${SLAMRUN_INCLUDE_DIR})\n"
          "  ADD_DEFINITIONS(-DSLAMRUN_PARAMS)\n"
          "  INCLUDE_DIRECTORIES(${vikit_common_INCLUDE_DIRS})\n")
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
    append_line(root, cm, "\n# slamrun: the ROS-free offline driver (docker/cnn_svo/cnn_svo_offline.cpp)\n"
                "ADD_EXECUTABLE(cnn_svo_offline ${SLAMRUN_SVO_DRIVER})\n"
                "TARGET_LINK_LIBRARIES(cnn_svo_offline svo ${LINK_LIBS})")
    # its g2o include line is commented out (upstream relied on ROS Kinetic's /opt/ros/kinetic/include)
    patch(root, cm, "replace", "    #${G2O_INCLUDE_DIR}\n", "    ${G2O_INCLUDE_DIR}  # slamrun\n")
    # Boost >= 1.73 no longer puts bind's _1/_2 in the global namespace (boost::bind(..., _1, _2) in the
    # frame handlers); global.h is included by every source
    patch(root, os.path.join(SVO, "include/svo/global.h"), "after", "#include <boost/shared_ptr.hpp>\n",
          "#include <boost/bind/bind.hpp>\nusing namespace boost::placeholders;  // slamrun: Boost >= 1.73\n")
    sub(root, os.path.join(SVO, "src/config.cpp"), r"#ifdef SVO_USE_ROS\b",
        "#if defined(SVO_USE_ROS) || defined(SLAMRUN_PARAMS)", min_count=2)
    opencv4(root, [os.path.join(SVO, "src")])


if __name__ == "__main__":
    cnn_svo_root, sophus_root, fast_root = sys.argv[1], sys.argv[2], sys.argv[3]
    sophus(sophus_root)
    fast(fast_root)
    vikit_common(cnn_svo_root)
    svo(cnn_svo_root)
