"""monodepth-cpp @ 1ea2fc3 against the TensorFlow 2 C++ libraries of PyPI's tensorflow-cpu wheel (no Bazel).

- Its Find modules look for a Bazel tree (/usr/local/include/google/tensorflow, external/nsync) and a system
  protobuf, and ignore -DTensorflow_DIR/-DTENSORFLOW_INCLUDE_DIR/-DTENSORFLOW_LIB_DIR: use the wheel's
  tensorflow/include (it carries TF's own protobuf 6.31, Abseil 20250814 and Eigen headers) and link
  libtensorflow_cc.so.2 + libtensorflow_framework.so.2 (protobuf's symbols are exported by the latter),
  given as -DTENSORFLOW_ROOT=<the wheel's tensorflow/ folder>.
- TF 2.21's headers require C++17 (absl/base/policy_checks.h: "C++ versions less than C++17 are not supported").
  monodepth.cpp is the only TensorFlow-facing translation unit; monodepth.h exposes only OpenCV/std types
  (pimpl), so the programs that use it (CNN-DSO, CNN-SVO) stay C++11/14.
- The wheel's Eigen comes before the system's (the system Eigen 3.4 must not mix with TF's tensor headers).
- tensorflow::Status is absl::Status in TF >= 2.13: Status::OK() no longer exists (absl::OkStatus()).
usage: patches.py MONODEPTH_ROOT
"""
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "common"))
from patchlib import patch, sub  # noqa: E402

TF_BLOCK = """# slamrun: TensorFlow 2 C++ from the tensorflow-cpu wheel (-DTENSORFLOW_ROOT=<wheel>/tensorflow)
IF(NOT TENSORFLOW_ROOT OR NOT EXISTS ${TENSORFLOW_ROOT}/libtensorflow_cc.so.2)
  MESSAGE(FATAL_ERROR "set -DTENSORFLOW_ROOT to the tensorflow/ folder of the wheel (libtensorflow_cc.so.2, include/)")
ENDIF()
SET(TensorFlow_INCLUDE_DIRS ${TENSORFLOW_ROOT}/include)
SET(TensorFlow_LIBRARIES ${TENSORFLOW_ROOT}/libtensorflow_cc.so.2 ${TENSORFLOW_ROOT}/libtensorflow_framework.so.2)
SET(PROTOBUF_INCLUDE_DIRS "")
SET(PROTOBUF_LIBRARIES "")
"""


def monodepth_cpp(root):
    sub(root, "CMakeLists.txt", r"-std=c\+\+11", "-std=c++17")
    patch(root, "CMakeLists.txt", "replace", "FIND_PACKAGE(Protobuf REQUIRED)\nFIND_PACKAGE(TensorFlow REQUIRED)\n",
          TF_BLOCK)
    patch(root, "CMakeLists.txt", "replace",
          "  include\n  ${EIGEN3_INCLUDE_DIR}\n  ${OpenCV_INCLUDE_DIRS}\n  ${PROTOBUF_INCLUDE_DIRS}\n"
          "  ${TensorFlow_INCLUDE_DIRS}\n",
          "  include\n  ${TensorFlow_INCLUDE_DIRS}\n  ${OpenCV_INCLUDE_DIRS}\n")
    # the test program hard-codes ../model/model_city2kitti.pb and ../data/: not built
    patch(root, "CMakeLists.txt", "replace",
          "ADD_EXECUTABLE(inference_monodepth src/inference_monodepth.cpp)\n"
          "TARGET_LINK_LIBRARIES(inference_monodepth ${PROJECT_NAME})",
          "# slamrun: inference_monodepth (hard-coded paths) not built")
    sub(root, "src/monodepth.cpp", r"return Status::OK\(\);", "return absl::OkStatus();", min_count=2)


if __name__ == "__main__":
    monodepth_cpp(sys.argv[1])
