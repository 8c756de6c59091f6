"""ORB-SLAM2 patches: no viewer in mono_tum, a loop-closure switch, usleep's header for newer gcc."""
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "common"))
from patchlib import include_once, patch  # noqa: E402

root = sys.argv[1]

# Headless: the viewer flag is hard-coded on in mono_tum.cc.
patch(root, "Examples/Monocular/mono_tum.cc", "replace",
      "ORB_SLAM2::System SLAM(argv[1],argv[2],ORB_SLAM2::System::MONOCULAR,true);",
      "ORB_SLAM2::System SLAM(argv[1],argv[2],ORB_SLAM2::System::MONOCULAR,false);")

# Loop closure off when ORB_SLAM2_NO_LOOP is set: keyframes still enter the database, no loop is searched.
patch(root, "src/LoopClosing.cc", "after", "bool LoopClosing::DetectLoop()\n{", """
    if (getenv("ORB_SLAM2_NO_LOOP"))  // slamrun: loop closure switch
    {
        unique_lock<mutex> lock(mMutexLoopQueue);
        mpCurrentKF = mlpLoopKeyFrameQueue.front();
        mlpLoopKeyFrameQueue.pop_front();
        mpKeyFrameDB->add(mpCurrentKF);
        return false;
    }
""")
include_once(root, "src/LoopClosing.cc", "cstdlib")

# gcc >= 7 needs unistd.h for usleep.
for f in ("src/System.cc", "src/Tracking.cc", "src/LocalMapping.cc", "src/LoopClosing.cc", "src/Viewer.cc",
          "Examples/Monocular/mono_tum.cc"):
    include_once(root, f, "unistd.h")
