"""LSD-SLAM (tum-vision/lsd_slam @ d1e6f0e) without ROS on Debian 12: its core sources are compiled by the
project's CMakeLists.txt (slamrun/methods/lsd_slam/image, replacing the rosbuild one) with a headless ImageDisplay and the
offline driver lsd_slam_offline.cpp; these patches make the upstream sources build with gcc 12, OpenCV 4.6,
Boost 1.74 and Eigen 3.4.

- OpenCV 4 constants (CV_GRAY2RGB, CV_LOAD_IMAGE_*, ...) below lsd_slam_core/src, and the C API's cvPoint()
  (util/globalFuncs.cpp) as cv::Point.
- Boost >= 1.73 no longer puts bind's _1.._3 in the global namespace: util/IndexThreadReduce.h (included by
  DepthMap.cpp, whose boost::bind calls use them) brings boost::placeholders in, as DSO's patch does.
- gcc >= 9's libstdc++ requires a container's allocator to allocate its value_type: the keyed containers' pairs
  get their `Key const` (Frame.h's trackingFailed, SlamSystem.cpp's candidateToFrame_initialEstimateMap) and
  KeyFrameGraph.h's newEdgeBuffer of KFConstraintStruct* gets an allocator of KFConstraintStruct* (upstream:
  of FramePoseStruct*). Same layout, same behaviour.
usage: patches.py LSD_SLAM_ROOT
"""
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "common"))
sys.path.insert(1, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "recipes", "common"))  # in slamrun's tree
from patchlib import opencv4, patch, sub  # noqa: E402

CORE = "lsd_slam_core"


def lsd_slam(root):
    src = os.path.join(CORE, "src")
    opencv4(root, [src])
    sub(root, os.path.join(src, "util/globalFuncs.cpp"), r"\bcvPoint\(", "cv::Point(", min_count=2)
    patch(root, os.path.join(src, "util/IndexThreadReduce.h"), "after", '#include "boost/thread.hpp"\n',
          "#include <boost/bind/bind.hpp>\nusing namespace boost::placeholders;  // slamrun: Boost >= 1.73\n")
    patch(root, os.path.join(src, "DataStructures/Frame.h"), "replace",
          "Eigen::aligned_allocator< std::pair<const Frame*,Sim3> > > trackingFailed;",
          "Eigen::aligned_allocator< std::pair<Frame* const,Sim3> > > trackingFailed;  // slamrun: gcc >= 9")
    patch(root, os.path.join(src, "SlamSystem.cpp"), "replace",
          "Eigen::aligned_allocator<std::pair<Frame*, Sim3> > > candidateToFrame_initialEstimateMap;",
          "Eigen::aligned_allocator<std::pair<Frame* const, Sim3> > > candidateToFrame_initialEstimateMap;"
          "  // slamrun: gcc >= 9")
    patch(root, os.path.join(src, "GlobalMapping/KeyFrameGraph.h"), "replace",
          "std::vector< KFConstraintStruct*, Eigen::aligned_allocator<FramePoseStruct*> > newEdgeBuffer;",
          "std::vector< KFConstraintStruct*, Eigen::aligned_allocator<KFConstraintStruct*> > newEdgeBuffer;"
          "  // slamrun: gcc >= 9")


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: patches.py LSD_SLAM_ROOT")
    lsd_slam(sys.argv[1])
