"""DSM @ 36ab5cf on Debian 12 (gcc 12, OpenCV 4.6, Ceres 2.1, Eigen 3.4), headless: FullSystem.h uses
std::condition_variable without <condition_variable> (gcc 12's <mutex>/<thread> no longer pull it in), and
the top level builds only the library and our driver (QtVisualizer and the Qt examples are skipped, so Qt/GL
are not needed). usage: patches.py DSM_ROOT"""
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "common"))
sys.path.insert(1, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "recipes", "common"))  # in slamrun's tree
from patchlib import patch  # noqa: E402

if __name__ == "__main__":
    root = sys.argv[1]
    patch(root, "dsm/src/FullSystem/FullSystem.h", "after", "#include <mutex>\n", "#include <condition_variable>\n")
    # the file has no trailing newline; Headless/ holds slamrun's driver (CMakeLists.txt + dsm_headless.cpp)
    patch(root, "CMakeLists.txt", "replace", "add_subdirectory(QtVisualizer)\nadd_subdirectory(Examples)",
          "add_subdirectory(Headless)  # slamrun: library + headless driver only (no Qt)\n")
