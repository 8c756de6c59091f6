"""DynaSLAM @ 8f894a8 (ORB-SLAM2 + Mask R-CNN through the Python 2.7 C API) on Debian 11 (gcc 10, OpenCV 4.5,
Eigen 3.3, Boost 1.74, Python 2.7.18 with numpy 1.16 from PyPI), monocular, headless.

- The ORB-SLAM2 family (slamrun/methods/recipes/common/families.py): the OpenCV 4 / gcc >= 8 / C++14 toolchain fixes DynaSLAM
  shares with ORB-SLAM2 (its CMakeLists asks for OpenCV 2.4.11, then 3.0), the loop-closure switch
  (ORB_SLAM2_NO_LOOP=1) and usleep's header.
- CMakeLists.txt: the lines building Examples/Monocular/mono_carla.cc, a file HEAD no longer has, removed;
  PythonLibs asked for 2.7 (a Python 3 -dev package must not be taken); numpy's headers from the numpy Python
  2.7 imports (pip puts it in /usr/local/lib/python2.7/dist-packages, not where upstream looks); Qt5 not
  looked for (nothing includes or links it).
- src/Conversion.cc: replaced by slamrun/methods/dynaslam/image/Conversion.cc, a copying numpy <-> cv::Mat conversion
  (upstream's OpenCV >= 3 allocator turns a reference count's address into a PyObject*; see that file).
- src/MaskNet.cc: a Python error (import, weights, a frame) is printed and ends the run instead of an assert
  compiled out of the release build (then a crash on a null pointer); the frame and mask arrays are released
  after each frame (upstream leaks both: 3.4 MB a frame).
- Examples/Monocular/mono_tum.cc: the viewer off; the mask file name: upstream strips 4 characters
  (`rgb/` of TUM RGB-D), so with `images/x.png` masks went to MASKDIR/ges/x.png, a folder that never exists,
  and imwrite failed silently (no cache). The file's base name is used instead.
- src/python/coco.py: pycocotools imported only if present: MaskRCNN.py imports coco for CocoConfig alone, and
  pycocotools (COCO's dataset API and evaluator: training and evaluation, not inference) has no Python 2 wheel.
usage: patches.py DYNASLAM_ROOT
"""
import os
import shutil
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "common"))
sys.path.insert(1, os.path.join(HERE, "..", "..", "recipes", "common"))  # in slamrun's tree
from families import orb_slam2_family, orb_slam2_toolchain  # noqa: E402
from patchlib import include_once, patch  # noqa: E402

NUMPY_INCLUDE = """execute_process(COMMAND python2.7 -c "import numpy; print(numpy.get_include())"
                OUTPUT_VARIABLE SLAMRUN_NUMPY_INCLUDE OUTPUT_STRIP_TRAILING_WHITESPACE RESULT_VARIABLE slamrun_np)
if(NOT slamrun_np EQUAL 0)
    message(FATAL_ERROR "numpy for python2.7 not found (its headers build src/Conversion.cc)")
endif()
"""

PY_FAIL = '{ PyErr_Print(); std::cerr << "DynaSLAM: %s failed (the Python error is above)" << std::endl; exit(1); }'


def dynaslam(root):
    orb_slam2_toolchain(root, requested="2.4.11")
    cm = "CMakeLists.txt"
    patch(root, cm, "replace",
          "add_executable(mono_carla\nExamples/Monocular/mono_carla.cc)\n"
          "target_link_libraries(mono_carla ${PROJECT_NAME})\n", "")
    patch(root, cm, "replace", "find_package(PythonLibs REQUIRED)", "find_package(PythonLibs 2.7 REQUIRED)  # slamrun")
    for qt in ("Widgets", "Concurrent", "OpenGL", "Test"):
        patch(root, cm, "replace", "find_package(Qt5%s REQUIRED)\n" % qt, "")
    patch(root, cm, "before", "include_directories(\n", NUMPY_INCLUDE)
    patch(root, cm, "replace", "/usr/lib/python2.7/dist-packages/numpy/core/include/numpy/",
          "${SLAMRUN_NUMPY_INCLUDE}/numpy")
    conversion = os.path.join(root, "src", "Conversion.cc")
    patch(root, "src/Conversion.cc", "replace", "m.u->refcount = *refcountFromPyObject(o);",
          "m.u->refcount = *refcountFromPyObject(o);")  # the anchor: upstream's file is the one described above
    shutil.copyfile(os.path.join(HERE, "Conversion.cc"), conversion)
    print("patch: src/Conversion.cc (replaced by slamrun/methods/dynaslam/image/Conversion.cc)")
    mask = "src/MaskNet.cc"
    for what, line in (("importing the Mask R-CNN module", "assert(this->py_module != NULL);"),
                       ("finding its class", "assert(this->py_class != NULL);"),
                       ("loading Mask R-CNN", "assert(this->net != NULL);")):
        patch(root, mask, "replace", line, "if (!%s) %s  // slamrun" % (line[7:-2].split(" ")[0], PY_FAIL % what))
    patch(root, mask, "after", "seg = cvt->toMat(py_mask_image).clone();",
          "\n        Py_DECREF(py_mask_image); Py_DECREF(py_image);  // slamrun: no leak per frame")
    patch(root, mask, "before", "        seg = cvt->toMat(py_mask_image).clone();",
          "        if (!py_mask_image) %s  // slamrun\n" % (PY_FAIL % "Mask R-CNN on a frame"))
    mono = "Examples/Monocular/mono_tum.cc"
    patch(root, mono, "replace", "ORB_SLAM2::System SLAM(argv[1],argv[2],ORB_SLAM2::System::MONOCULAR,true);",
          "ORB_SLAM2::System SLAM(argv[1],argv[2],ORB_SLAM2::System::MONOCULAR,false);  // slamrun: no viewer")
    patch(root, mono, "replace",
          'MaskNet->GetSegmentation(im,string(argv[4]),vstrImageFilenames[ni].replace(0,4,""));',
          "MaskNet->GetSegmentation(im,string(argv[4]),"
          "vstrImageFilenames[ni].substr(vstrImageFilenames[ni].find_last_of('/')+1));  // slamrun: base name")
    patch(root, "src/python/coco.py", "replace",
          "from pycocotools.coco import COCO\nfrom pycocotools.cocoeval import COCOeval\n"
          "from pycocotools import mask as maskUtils\n",
          "try:  # slamrun: COCO's dataset API and evaluator (training, evaluation), not needed for inference\n"
          "    from pycocotools.coco import COCO\n    from pycocotools.cocoeval import COCOeval\n"
          "    from pycocotools import mask as maskUtils\nexcept ImportError:\n"
          "    COCO = COCOeval = maskUtils = None\n")
    for header in ("sys/stat.h", "sys/time.h"):  # mkdir, gettimeofday: no longer included transitively
        include_once(root, mask, header)
    orb_slam2_family(root, [mono, mask])


if __name__ == "__main__":
    dynaslam(sys.argv[1])
