"""DF-ORB-SLAM (834810269/DF-ORB-SLAM @ 462425d) on Debian 12 (gcc 12, OpenCV 4.6, Eigen 3.4, Pangolin v0.6),
monocular and headless: our offline driver mono_tum_df, the monocular optical-flow fix, the loop-closure switch
(ORB_SLAM2_NO_LOOP=1), the modern-toolchain fixes, and a core library without catkin/ROS, PCL, glog or libtiff.
Every edit is anchored: an upstream change fails the build naming the file and the anchor."""
import os
import shutil
import sys

here = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(here, "..", "common"))
sys.path.insert(1, os.path.join(here, "..", "..", "recipes", "common"))  # in slamrun's tree
from families import orb_slam2_family, orb_slam2_toolchain  # noqa: E402
from patchlib import append_line, patch  # noqa: E402

root = sys.argv[1]


def require(path, text):
    """Fail unless `text` occurs exactly once in `path` (a statement a fix relies on)."""
    with open(os.path.join(root, path), encoding="utf-8", errors="surrogateescape") as f:
        src = f.read()
    if src.count(text) != 1:
        sys.exit("patch: %s: expected %r once, found %d times (did upstream change?)" % (path, text, src.count(text)))


# --- Monocular: DF-ORB-SLAM's LK matcher never gets images -------------------------------------------------
# TrackWithMotionModel calls ORBmatcher::SearchByLK(..., mImPre, mImCur), which runs calcOpticalFlowPyrLK on
# them (src/ORBmatcher.cc). Only GrabImageRGBD fills them: `clahe->apply(mImGray,mImCur);` after the Frame is
# built and `mImPre=mImCur.clone();` after Track(). GrabImageMonocular gets the same two steps in the same places.
require("src/ORBmatcher.cc", "const bool bMono, const cv::Mat &mImgPre, const cv::Mat &mImgCur)\n{")
require("src/ORBmatcher.cc", "\n    cv::calcOpticalFlowPyrLK(mImgPre,mImgCur,")
require("src/Tracking.cc", "matcher.SearchByLK(mCurrentFrame,mLastFrame,th,mSensor==System::MONOCULAR,mImPre,mImCur);")
require("src/Tracking.cc", "    clahe->apply(mImGray,mImCur);// --wang\n\n    Track();\n\n    mImPre=mImCur.clone(); // --wang\n")
patch(root, "src/Tracking.cc", "replace",
      "        mCurrentFrame = Frame(mImGray,timestamp,mpORBextractorLeft,mpORBVocabulary,mK,mDistCoef,mbf,mThDepth);\n"
      "\n    Track();\n",
      "        mCurrentFrame = Frame(mImGray,timestamp,mpORBextractorLeft,mpORBVocabulary,mK,mDistCoef,mbf,mThDepth);\n"
      "\n    clahe->apply(mImGray,mImCur); // slamrun: fill the LK images as GrabImageRGBD does\n"
      "\n    Track();\n"
      "\n    mImPre=mImCur.clone(); // slamrun\n")
# SearchByLK also reads and writes Frame::mvTracked/mvPreObsID, sized only in ComputeStereoFromRGBD (RGB-D):
# a monocular frame left them empty (writes through an empty vector). Size them in the monocular constructor.
patch(root, "src/Frame.cc", "after",
      "    // Set no stereo information\n    mvuRight = vector<float>(N,-1);\n    mvDepth = vector<float>(N,-1);\n",
      "    // slamrun: LK tracking state, as ComputeStereoFromRGBD sets it on the RGB-D path\n"
      "    mvTracked.resize(N,1);\n    mvPreObsID.resize(N,-1);\n")
# SearchByLK crashes when fewer than 7 flow matches survive (findFundamentalMat returns no 3x3 matrix and no
# mask; F.at<double> and status[i] then read nothing): report no LK match, so TrackWithMotionModel falls back
# to SearchByProjection as it does for < 20 matches. And a point whose candidates all have map points left
# bestIdx2 = -1 and indexed mvKeysUn[-1] (discarded afterwards anyway: skip it before the read).
patch(root, "src/ORBmatcher.cc", "after",
      "    CurrentFrame.F = cv::findFundamentalMat(F_prepoints,F_curpoints,cv::FM_RANSAC, 1, 0.99, status);\n",
      "    if(CurrentFrame.F.rows!=3 || CurrentFrame.F.cols!=3 || status.size()!=F_prepoints.size())\n"
      "        return 0; // slamrun: too few LK matches for a fundamental matrix\n")
patch(root, "src/ORBmatcher.cc", "before",
      "            cv::Point2f p=LastFrame.mvKeysUn[i].pt;\n",
      "            if(bestIdx2<0) continue; // slamrun: no candidate left\n")

# Every pose optimisation of DF-ORB-SLAM is PoseOptimizationEM, which weighs each edge by
# 1-|z-d|/|z+d| (z: projected depth, d: the keypoint's measured depth). A monocular frame has d = -1 for
# every keypoint, so every weight is negative (z > 0) and the pose is pushed away from the data: the map is
# lost a few frames after each initialisation. Upstream behaviour stays the default; with the environment
# variable DF_ORB_SLAM_MONO_POSE=orb a frame without any depth uses ORB-SLAM2's PoseOptimization (same file).
# (The driver mono_tum_df also sets it from the settings file: `Slamrun.env.DF_ORB_SLAM_MONO_POSE: "orb"`.)
patch(root, "src/Optimizer.cc", "after", "int Optimizer::PoseOptimizationEM(Frame *pFrame)\n{\n",
      "    // slamrun: opt-in switch for frames without depth (monocular), where the EM weights are negative\n"
      "    static const bool bMonoPoseOrb = getenv(\"DF_ORB_SLAM_MONO_POSE\") &&\n"
      "                                     string(getenv(\"DF_ORB_SLAM_MONO_POSE\")) == \"orb\";\n"
      "    if(bMonoPoseOrb && (pFrame->mvDepth.empty() ||\n"
      "                        *max_element(pFrame->mvDepth.begin(), pFrame->mvDepth.end()) < 0))\n"
      "        return PoseOptimization(pFrame);\n\n")
# (not include_once: Optimizer.cc starts with a UTF-8 byte-order mark, which must stay first)
patch(root, "src/Optimizer.cc", "after", '#include "Converter.h"\n', "#include <algorithm>\n#include <cstdlib>\n")

# --- Core library without PCL, ROS, glog, libtiff ----------------------------------------------------------
# Only src/pointcloudmapping.cpp (+ its SLIC.cpp) uses PCL and ROS; nothing uses glog or libtiff (they were
# hard-coded link paths of the authors' machine). The dense mapping is RGB-D only and off unless bMapping:
# compile it out and give the headers a stub class (pointcloud_off.h, see there).
shutil.copy(os.path.join(here, "pointcloud_off.h"), os.path.join(root, "include", "pointcloud_off.h"))
print("patch: include/pointcloud_off.h (added)")
for f in ("include/System.h", "include/Tracking.h", "include/LoopClosing.h", "src/LoopClosing.cc"):
    patch(root, f, "replace", '#include "pointcloudmapping.h"', '#include "pointcloud_off.h" // slamrun: no PCL/ROS')
cm = "CMakeLists.txt"
patch(root, cm, "replace", 'find_package(PCL 1.7 REQUIRED)\nif(PCL_FOUND)\n   message("PCL FOUND")\nendif()\n', "")
patch(root, cm, "replace",
      "find_package(catkin REQUIRED COMPONENTS\n        roscpp\n        sensor_msgs\n        message_generation\n"
      "        tf\n)\n", "")
# (${PCL_*} and ${catkin_*} references stay: without find_package they expand to nothing.)
patch(root, cm, "replace", "src/pointcloudmapping.cpp\nsrc/SLIC.cpp\n", "")
patch(root, cm, "replace", "/usr/lib/x86_64-linux-gnu/libtiff.so.5 \n", "")
patch(root, cm, "replace", "/usr/lib/x86_64-linux-gnu/libglog.so\n-lboost_system\n", "")

# --- Toolchain: OpenCV 4, gcc >= 8, C++14 (as ORB-SLAM2, whose patch function this shares) -----------------
orb_slam2_toolchain(root, requested="3.4", sources=("src",))

# --- Offline monocular driver (Examples/Monocular/ does not exist upstream) --------------------------------
os.makedirs(os.path.join(root, "Examples", "Monocular"), exist_ok=True)
for name in ("mono_tum_df.cc", "mono_tum_df.cmake"):
    shutil.copy(os.path.join(here, name), os.path.join(root, "Examples", "Monocular", name))
    print("patch: Examples/Monocular/%s (added)" % name)
append_line(root, cm, "include(${PROJECT_SOURCE_DIR}/Examples/Monocular/mono_tum_df.cmake) # slamrun")

# --- Loop-closure switch (ORB_SLAM2_NO_LOOP=1) and usleep's header (gcc >= 7) ------------------------------
orb_slam2_family(root, ["src/Viewer.cc"])
