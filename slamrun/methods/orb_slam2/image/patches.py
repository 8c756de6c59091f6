"""ORB-SLAM2 (raulmur/ORB_SLAM2 @ f2e6f51) on Debian 12 (gcc 12, OpenCV 4.6, Eigen 3.4, Pangolin v0.6):
mono_tum without viewer, a loop-closure switch (ORB_SLAM2_NO_LOOP=1), and the modern-toolchain fixes.
Every edit is anchored: an upstream change fails the build naming the file and the anchor."""
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "common"))
sys.path.insert(1, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "recipes", "common"))  # in slamrun's tree
from families import orb_slam2_family, orb_slam2_toolchain  # noqa: E402
from patchlib import patch  # noqa: E402

if __name__ == "__main__":
    root = sys.argv[1]
    orb_slam2_toolchain(root)
    # Headless: the viewer flag is hard-coded on in mono_tum.cc.
    patch(root, "Examples/Monocular/mono_tum.cc", "replace",
          "ORB_SLAM2::System SLAM(argv[1],argv[2],ORB_SLAM2::System::MONOCULAR,true);",
          "ORB_SLAM2::System SLAM(argv[1],argv[2],ORB_SLAM2::System::MONOCULAR,false);")
    # Loop-closure switch (ORB_SLAM2_NO_LOOP=1) and usleep's header (gcc >= 7).
    orb_slam2_family(root, ["src/Viewer.cc", "Examples/Monocular/mono_tum.cc"])
