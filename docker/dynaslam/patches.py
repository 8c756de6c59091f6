"""DynaSLAM @ 8f894a8 (ORB-SLAM2 + Mask R-CNN through the Python 2.7 C API), monocular, headless.

- CMakeLists.txt (~163-166): add_executable/target_link_libraries of Examples/Monocular/mono_carla.cc, a file
  HEAD no longer has: removed.
- CMakeLists.txt (~37): find_package(OpenCV 2.4.11) -> 2.4.9 (Ubuntu 16.04's libopencv-dev 2.4.9.1; DynaSLAM's
  numpy<->cv::Mat allocator in src/Conversion.cc is the OpenCV 2.4 one, its OpenCV 3 branch is reported to crash
  with masks, issue #51). The 3.0 fallback stays.
- Examples/Monocular/mono_tum.cc: the viewer off; the mask file name: upstream strips 4 characters
  (`rgb/` of TUM RGB-D), so with `images/x.png` masks went to MASKDIR/ges/x.png, a folder that never exists,
  and imwrite failed silently (no cache). The file's base name is used instead.
- ORB-SLAM2 family: the loop-closure switch (ORB_SLAM2_NO_LOOP=1) and usleep's header.
usage: patches.py DYNASLAM_ROOT
"""
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "common"))
from families import orb_slam2_family  # noqa: E402
from patchlib import patch  # noqa: E402


def dynaslam(root):
    patch(root, "CMakeLists.txt", "replace",
          "add_executable(mono_carla\nExamples/Monocular/mono_carla.cc)\n"
          "target_link_libraries(mono_carla ${PROJECT_NAME})\n", "")
    patch(root, "CMakeLists.txt", "replace", "find_package(OpenCV 2.4.11 QUIET)", "find_package(OpenCV 2.4.9 QUIET)")
    mono = "Examples/Monocular/mono_tum.cc"
    patch(root, mono, "replace", "ORB_SLAM2::System SLAM(argv[1],argv[2],ORB_SLAM2::System::MONOCULAR,true);",
          "ORB_SLAM2::System SLAM(argv[1],argv[2],ORB_SLAM2::System::MONOCULAR,false);  // slamrun: no viewer")
    patch(root, mono, "replace",
          'MaskNet->GetSegmentation(im,string(argv[4]),vstrImageFilenames[ni].replace(0,4,""));',
          "MaskNet->GetSegmentation(im,string(argv[4]),"
          "vstrImageFilenames[ni].substr(vstrImageFilenames[ni].find_last_of('/')+1));  // slamrun: base name")
    orb_slam2_family(root, [mono])


if __name__ == "__main__":
    dynaslam(sys.argv[1])
