"""DSO @ 7b0c99f on Debian 12 (gcc 12, Boost 1.74, OpenCV 4.6): Boost's `_1` placeholders (no longer in the
global namespace), OpenCV 4's cv::IMREAD_* constants and C++14 (Boost 1.74 and Eigen 3.4 need more than
-std=c++0x). usage: patches.py DSO_ROOT"""
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "common"))
sys.path.insert(1, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "recipes", "common"))  # in slamrun's tree
from families import dso_family  # noqa: E402

if __name__ == "__main__":
    dso_family(sys.argv[1])
