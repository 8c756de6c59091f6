"""LDSO @ 9b0c48c on Debian 12 (gcc 12, OpenCV 4.6, Boost 1.74, Eigen 3.4), headless.

- thirdparty/DBoW3/src/BowVector.h relies on <cstdint>, <cstddef>, <iostream>, <string> coming with other
  headers, which gcc 12's library no longer does.
- src/frontend/FeatureMatcher.cc calls _mm_popcnt_u64 on a 32-bit value: it exists only with -mpopcnt
  (a native build on the authors' CPUs); __builtin_popcount is the same count on any target.
- examples/run_dso_tum_mono.cc saves the viewer's point cloud through a null viewer with nogui=1 (a
  segfault at exit after the results were written): only with a viewer.
usage: patches.py LDSO_ROOT"""
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "common"))
sys.path.insert(1, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "recipes", "common"))  # in slamrun's tree
from patchlib import patch  # noqa: E402

if __name__ == "__main__":
    root = sys.argv[1]
    patch(root, "thirdparty/DBoW3/src/BowVector.h", "after", "#include <map>\n#include <vector>\n",
          "#include <cstdint>\n#include <cstddef>\n#include <iostream>\n#include <string>  // slamrun: gcc 12\n")
    patch(root, "src/frontend/FeatureMatcher.cc", "replace", "dist += _mm_popcnt_u64(v);",
          "dist += __builtin_popcount(v);  // slamrun: v is 32 bits; portable")
    patch(root, "examples/run_dso_tum_mono.cc", "replace", '    viewer->saveAsPLYFile("./pointcloud.ply");',
          '    if (viewer) viewer->saveAsPLYFile("./pointcloud.ply");  // slamrun: nogui=1 has no viewer')
