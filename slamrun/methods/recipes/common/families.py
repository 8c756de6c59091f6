"""Patch families: the edits a group of recipes shares because their upstreams share code (ORB-SLAM2 and its
forks, DSO and its forks, SVO and CNN-SVO with Sophus, fast and rpg_vikit). Each recipe's patches.py imports
them from here (slamrun/methods/recipes/common is copied into every build), then adds its own. Built on patchlib's anchored
edits: an upstream change fails the build naming the file and the anchor."""
import os
import sys

from patchlib import append_line, cxx_standard, include_once, opencv4, patch, sub

# ------------------------------------------------------------------------------------------- ORB-SLAM2

LOOP_SWITCH = """
    if (getenv("ORB_SLAM2_NO_LOOP"))  // slamrun: loop closure switch
    {
        unique_lock<mutex> lock(mMutexLoopQueue);
        mpCurrentKF = mlpLoopKeyFrameQueue.front();
        mlpLoopKeyFrameQueue.pop_front();
        mpKeyFrameDB->add(mpCurrentKF);
        return false;
    }
"""


def orb_slam2_family(root, extra_sources=()):
    """The patches every ORB-SLAM2-based method needs: the loop-closure switch (ORB_SLAM2_NO_LOOP=1 leaves
    keyframes in the database but searches no loop) and usleep's header for gcc >= 7."""
    patch(root, "src/LoopClosing.cc", "after", "bool LoopClosing::DetectLoop()\n{", LOOP_SWITCH)
    include_once(root, "src/LoopClosing.cc", "cstdlib")
    for f in ("src/System.cc", "src/Tracking.cc", "src/LocalMapping.cc", "src/LoopClosing.cc") + tuple(extra_sources):
        include_once(root, f, "unistd.h")


def orb_slam2_toolchain(root, requested="3.0", sources=("src", "Examples/Monocular")):
    """Debian 12's toolchain for ORB-SLAM2's layout (ORB-SLAM2, DF-ORB-SLAM): OpenCV 4, gcc >= 8, C++14.
    `requested` is the OpenCV version the main CMakeLists asks for (DF-ORB-SLAM: 3.4), `sources` the folders
    holding OpenCV C constants."""
    # OpenCV 4: the CMake files ask for 3.x (then 2.4.3); OpenCV 4's version file accepts only 4.x requests.
    patch(root, "CMakeLists.txt", "replace", "find_package(OpenCV %s QUIET)" % requested, "find_package(OpenCV 4 QUIET)")
    patch(root, "Thirdparty/DBoW2/CMakeLists.txt", "replace", "find_package(OpenCV 3.0 QUIET)",
          "find_package(OpenCV 4 QUIET)")
    # OpenCV 4 removed opencv/cv.h (ORBextractor.h's only OpenCV include) and the C constants.
    patch(root, "include/ORBextractor.h", "replace", "#include <opencv/cv.h>",
          "#include <opencv2/core/core.hpp>\n#include <opencv2/imgproc/imgproc.hpp>\n"
          "#include <opencv2/features2d/features2d.hpp>")
    # PnPsolver.h/.cc use the C API (CvMat, cvSVD, cvSolve, CV_SVD*), which came in through opencv/cv.h.
    include_once(root, "include/PnPsolver.h", "opencv2/core/core_c.h")
    opencv4(root, sources)
    # gcc >= 8: std::map's allocator must allocate pair<const Key, T>, the key being KeyFrame*.
    patch(root, "include/LoopClosing.h", "replace", "std::pair<const KeyFrame*, g2o::Sim3>",
          "std::pair<KeyFrame* const, g2o::Sim3>")
    # Eigen 3.4/Boost 1.74 headers want at least C++14 (COMPILEDWITHC11 stays defined: steady_clock).
    cxx_standard(root, "CMakeLists.txt", "-std=c++11")


# ------------------------------------------------------------------------------------------------- DSO

def dso_family(root):
    """What DSO and its forks (CNN-DSO) need on Debian 12: Boost's `_1` placeholders (no longer in the global
    namespace), OpenCV 4's cv::IMREAD_* constants, C++14 (Boost 1.74 and Eigen 3.4 need more than -std=c++0x)."""
    patch(root, "src/util/IndexThreadReduce.h", "after", '#include "boost/thread.hpp"\n',
          "#include <boost/bind/bind.hpp>\nusing namespace boost::placeholders;  // slamrun: Boost >= 1.73\n")
    opencv4(root, ["src/IOWrapper"])
    cxx_standard(root, "CMakeLists.txt", "-std=c++0x")


# ---------------------------------------------------------------------- SVO (rpg_svo, rpg_vikit, fast, Sophus)

def sophus_cxx11(root):
    """Sophus @ a621ff, sophus/so2.cpp: `unit_complex_.real() = 1.;` assigns to an rvalue since C++11
    (gcc >= 5): the complex number is set whole."""
    patch(root, "sophus/so2.cpp", "replace", "unit_complex_.real() = 1.;\n  unit_complex_.imag() = 0.;",
          "unit_complex_ = std::complex<double>(1, 0);  // slamrun: C++11")


def fast_cxx11(root):
    """fast: no test program (BUILD_TEST TRUE builds fast_test against OpenCV's highgui); -std=c++11 (gcc 12
    defaults to C++17, where fast's `register` variables are errors under its -Werror)."""
    patch(root, "CMakeLists.txt", "replace", "SET(BUILD_TEST TRUE)", "SET(BUILD_TEST FALSE)  # slamrun")
    patch(root, "CMakeLists.txt", "replace", 'SET(CMAKE_CXX_FLAGS "-Wall -Werror ',
          'SET(CMAKE_CXX_FLAGS "-std=c++11 -Wall -Werror ')


def vikit_common_without_ros(root, vikit_common="vikit_common"):
    """rpg_vikit's vikit_common (SVO's, or the copy CNN-SVO vendors): USE_ROS off, OpenCV 4 constants."""
    patch(root, os.path.join(vikit_common, "CMakeLists.txt"), "replace", "SET(USE_ROS TRUE)",
          "SET(USE_ROS FALSE)  # slamrun")
    opencv4(root, [os.path.join(vikit_common, "src")])
    sub(root, os.path.join(vikit_common, "src/homography.cpp"), r"\bCV_RANSAC\b", "cv::RANSAC")


def svo_without_ros(root, svo="svo", driver="svo_offline"):
    """rpg_svo's svo library (SVO's, or CNN-SVO's fork) without ROS: USE_ROS off; our include folder first
    (-DSLAMRUN_INCLUDE_DIR, the ROS-free vikit/params_helper.h in slamrun/methods/recipes/common/svo-include) and
    SLAMRUN_PARAMS (config.cpp reads its parameters through vk::getParam, with the ROS node's defaults,
    instead of the compiled-in non-ROS ones); Boost >= 1.73 bind placeholders in global.h; the offline driver
    target `driver` from -DSLAMRUN_SVO_DRIVER."""
    cm = os.path.join(svo, "CMakeLists.txt")
    patch(root, cm, "replace", "SET(USE_ROS TRUE)", "SET(USE_ROS FALSE)  # slamrun")
    patch(root, cm, "replace", "ELSE()\n  INCLUDE_DIRECTORIES(${vikit_common_INCLUDE_DIRS})\n",
          "ELSE()\n"
          "  # slamrun: a ROS-free vikit/params_helper.h, before anything else\n"
          "  INCLUDE_DIRECTORIES(BEFORE ${SLAMRUN_INCLUDE_DIR})\n"
          "  ADD_DEFINITIONS(-DSLAMRUN_PARAMS)\n"
          "  INCLUDE_DIRECTORIES(${vikit_common_INCLUDE_DIRS})\n")
    append_line(root, cm, "\n# slamrun: the ROS-free offline driver (-DSLAMRUN_SVO_DRIVER)\n"
                "ADD_EXECUTABLE(%s ${SLAMRUN_SVO_DRIVER})\n"
                "TARGET_LINK_LIBRARIES(%s svo ${LINK_LIBS})" % (driver, driver))
    sub(root, os.path.join(svo, "src/config.cpp"), r"#ifdef SVO_USE_ROS\b",
        "#if defined(SVO_USE_ROS) || defined(SLAMRUN_PARAMS)", min_count=2)
    # Boost >= 1.73 no longer puts bind's _1/_2 in the global namespace; global.h is included by every source
    patch(root, os.path.join(svo, "include/svo/global.h"), "after", "#include <boost/shared_ptr.hpp>\n",
          "#include <boost/bind/bind.hpp>\nusing namespace boost::placeholders;  // slamrun: Boost >= 1.73\n")


def drop_after(root, path, marker):
    """Cut a file at `marker` (found exactly once), keeping what stands before it."""
    full = os.path.join(root, path)
    with open(full, encoding="utf-8", errors="surrogateescape") as f:
        text = f.read()
    if text.count(marker) != 1:
        sys.exit("patch: %s: %r found %d times, expected once (did upstream change?)" % (path, marker[:50],
                                                                                        text.count(marker)))
    with open(full, "w", encoding="utf-8", errors="surrogateescape") as f:
        f.write(text[:text.index(marker)])
    print("patch: %s (cut at %r)" % (path, marker.strip()[:50]))

