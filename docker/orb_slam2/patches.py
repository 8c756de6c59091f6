"""ORB-SLAM2 (raulmur/ORB_SLAM2 @ f2e6f51) on Debian 12 (gcc 12, OpenCV 4.6, Eigen 3.4, Pangolin v0.6):
mono_tum without viewer, a loop-closure switch (ORB_SLAM2_NO_LOOP=1), and the modern-toolchain fixes.
Every edit is anchored: an upstream change fails the build naming the file and the anchor."""
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "common"))
from patchlib import cxx_standard, include_once, opencv4, orb_slam2_family, patch  # noqa: E402


def orb_slam2_toolchain(root, requested="3.0", sources=("src", "Examples/Monocular")):
    """Fixes shared with DF-ORB-SLAM (same layout): OpenCV 4, gcc >= 8, C++14. `requested` is the OpenCV
    version the main CMakeLists asks for (DF-ORB-SLAM: 3.4), `sources` the folders holding OpenCV C constants."""
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


if __name__ == "__main__":
    root = sys.argv[1]
    orb_slam2_toolchain(root)
    # Headless: the viewer flag is hard-coded on in mono_tum.cc.
    patch(root, "Examples/Monocular/mono_tum.cc", "replace",
          "ORB_SLAM2::System SLAM(argv[1],argv[2],ORB_SLAM2::System::MONOCULAR,true);",
          "ORB_SLAM2::System SLAM(argv[1],argv[2],ORB_SLAM2::System::MONOCULAR,false);")
    # Loop-closure switch (ORB_SLAM2_NO_LOOP=1) and usleep's header (gcc >= 7).
    orb_slam2_family(root, ["src/Viewer.cc", "Examples/Monocular/mono_tum.cc"])
