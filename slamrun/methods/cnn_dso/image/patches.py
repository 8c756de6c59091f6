"""CNN-DSO @ 46562f0 on Debian 12 against monodepth-cpp built on the tensorflow-cpu wheel's TF 2 C++.

Its CMakeLists (lines ~116-132) holds four placeholder paths (/abosolute/path/to/...) and one personal path
(/home/hide/Downloads/1.6/...): they become -DMONODEPTH_ROOT (monodepth-cpp's source tree, its build in
build/) and -DTENSORFLOW_ROOT (the wheel's tensorflow/ folder). No DSO translation unit needs TensorFlow's
headers: ImmaturePoint.cpp includes three it never uses (and TF 2.21's headers need C++17), so they go, and
DSO stays C++14. OpenCV 4: CV_GRAY2BGR in FullSystem.cpp. Then DSO's own fixes (dso_family).
usage: patches.py CNN_DSO_ROOT
"""
import os
import sys

here = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(here, "..", "common"))
sys.path.insert(1, os.path.join(here, "..", "..", "recipes", "common"))  # in slamrun's tree
from families import dso_family  # noqa: E402
from patchlib import opencv4, patch  # noqa: E402

TF_BLOCK = """#TensorFlow and monodepth (slamrun: monodepth-cpp built against the tensorflow-cpu wheel)
foreach(v MONODEPTH_ROOT TENSORFLOW_ROOT)
  if(NOT ${v})
    message(FATAL_ERROR "set -D${v} (monodepth-cpp's tree with build/, the wheel's tensorflow/ folder)")
  endif()
endforeach()
set(MONODEPTH_LIBRARY ${MONODEPTH_ROOT}/build/libmonodepth_static.a)
set(TENSORFLOW_LIBRARIES ${TENSORFLOW_ROOT}/libtensorflow_cc.so.2 ${TENSORFLOW_ROOT}/libtensorflow_framework.so.2)
set(monodepth_INCLUDE_DIRS ${MONODEPTH_ROOT}/include)
INCLUDE_DIRECTORIES(${monodepth_INCLUDE_DIRS})
"""


def cnn_dso(root):
    patch(root, "CMakeLists.txt", "replace",
          "#TensorFlow and monodepth\n"
          "include_directories(/abosolute/path/to/tensorflow/local/include/google/tensorflow)\n"
          "include_directories(/abosolute/path/to/tensorflow/bazel-tensorflow/external/nsync/public)\n"
          "set(monodepth_INCLUDE_DIRS /abosolute/path/to/monodepth/install/include)\n"
          "INCLUDE_DIRECTORIES(${monodepth_INCLUDE_DIRS})\n", TF_BLOCK)
    patch(root, "CMakeLists.txt", "replace", "/home/hide/Downloads/1.6/tensorflow/local/lib/libtensorflow_cc.so)",
          "${MONODEPTH_LIBRARY} ${TENSORFLOW_LIBRARIES})")
    patch(root, "CMakeLists.txt", "replace",
          "TARGET_LINK_LIBRARIES(dso_dataset /abosolute/path/to/monodepth-cpp/monodepth-lib/install/lib/"
          "libmonodepth_static.a)", "")
    with open(os.path.join(root, "CMakeLists.txt")) as f:
        left = [w for w in f.read().split() if w.startswith(("/abosolute", "/path/to", "/home/"))]
    if left:
        sys.exit("patch: CNN-DSO CMakeLists.txt still holds placeholder/personal paths: %s" % left[:5])
    patch(root, "src/FullSystem/ImmaturePoint.cpp", "replace",
          "#include <tensorflow/cc/client/client_session.h>\n#include <tensorflow/cc/ops/standard_ops.h>\n"
          "#include <tensorflow/core/framework/tensor.h>\n", "")
    opencv4(root, ["src/FullSystem"])
    dso_family(root)


if __name__ == "__main__":
    cnn_dso(sys.argv[1])
