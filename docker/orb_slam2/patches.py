"""ORB-SLAM2 patches: no viewer in mono_tum, a loop-closure switch, usleep's header for newer gcc."""
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "common"))
from patchlib import orb_slam2_family, patch  # noqa: E402

root = sys.argv[1]

# Headless: the viewer flag is hard-coded on in mono_tum.cc.
patch(root, "Examples/Monocular/mono_tum.cc", "replace",
      "ORB_SLAM2::System SLAM(argv[1],argv[2],ORB_SLAM2::System::MONOCULAR,true);",
      "ORB_SLAM2::System SLAM(argv[1],argv[2],ORB_SLAM2::System::MONOCULAR,false);")

# Loop-closure switch (ORB_SLAM2_NO_LOOP=1) and usleep's header.
orb_slam2_family(root, ["src/Viewer.cc", "Examples/Monocular/mono_tum.cc"])
