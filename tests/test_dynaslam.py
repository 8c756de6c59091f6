"""DynaSLAM's image (slamrun/methods/dynaslam/image): its patches on the real archive, its Python 2.7 packages (pinned
in
slamrun/images/sources.py, installed by hash), the fetch path refusing a wrong or missing wheel, its weights
choice, and Mask R-CNN loading under the image's Python 2.7 (when the image has been built)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from slamrun.images import sources as src
from slamrun.images.build import BuildOptions, model_choice, pypi_files_of, vocabulary_choice
from slamrun.images.sources import SourceError, obtain_pypi
from tests import images
from tests.conftest import UPSTREAM, loopback_server, recipe, require_upstream, unpack_upstream

ROOT = Path(__file__).resolve().parents[1]
RECIPE = recipe("dynaslam")
IMAGE = "slamrun/dynaslam:latest"


def patched_tree(tmp_path: Path) -> Path:
    root = unpack_upstream("dynaslam", tmp_path)
    res = subprocess.run([sys.executable, str(RECIPE / "patches.py"), str(root)], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    return root


def test_the_patches_port_the_real_tree_to_opencv_4_and_python_2_7_from_pypi(tmp_path):
    root = patched_tree(tmp_path)
    cmake = (root / "CMakeLists.txt").read_text()
    assert "find_package(OpenCV 4 QUIET)" in cmake and "find_package(OpenCV 2.4.11" not in cmake
    assert "-std=c++14" in cmake and "-std=c++11" not in cmake
    assert "mono_carla" not in cmake and "Qt5" not in cmake
    assert "find_package(PythonLibs 2.7 REQUIRED)" in cmake and "${SLAMRUN_NUMPY_INCLUDE}/numpy" in cmake
    assert "find_package(OpenCV 4 QUIET)" in (root / "Thirdparty/DBoW2/CMakeLists.txt").read_text()
    assert "opencv/cv.h" not in (root / "include/ORBextractor.h").read_text()
    assert "cv::SORT_EVERY_COLUMN + cv::SORT_DESCENDING" in (root / "src/Geometry.cc").read_text()
    for f in ("src", "Examples/Monocular"):
        for path in (root / f).rglob("*.c*"):
            assert "CV_LOAD_IMAGE" not in path.read_text(errors="replace"), path
    # the copying conversion replaces upstream's allocator, whose OpenCV >= 3 branch misreads a refcount
    conversion = (root / "src/Conversion.cc").read_text()
    assert conversion == (RECIPE / "Conversion.cc").read_text() and "refcountFromPyObject" not in conversion
    mask = (root / "src/MaskNet.cc").read_text()
    assert "assert(this->" not in mask and mask.count("PyErr_Print()") == 4
    assert "Py_DECREF(py_mask_image); Py_DECREF(py_image);" in mask
    mono = (root / "Examples/Monocular/mono_tum.cc").read_text()
    assert "MONOCULAR,false);" in mono and 'replace(0,4,"")' not in mono
    assert 'getenv("ORB_SLAM2_NO_LOOP")' in (root / "src/LoopClosing.cc").read_text()
    coco = (root / "src/python/coco.py").read_text()
    assert "except ImportError:\n    COCO = COCOeval = maskUtils = None" in coco
    # pycocotools is used by coco.py's dataset and evaluation code only, never by what MaskRCNN.py takes
    assert "coco.CocoConfig" in (root / "src/python/MaskRCNN.py").read_text()
    assert "pycocotools" not in (root / "src/python/model.py").read_text()


def test_the_patches_stop_on_an_upstream_change(tmp_path):
    root = unpack_upstream("dynaslam", tmp_path)
    path = root / "src/Conversion.cc"
    path.write_text(path.read_text().replace("m.u->refcount = *refcountFromPyObject(o);", "m.u->refcount = 1;"))
    res = subprocess.run([sys.executable, str(RECIPE / "patches.py"), str(root)], capture_output=True, text=True)
    assert res.returncode != 0 and "src/Conversion.cc" in res.stderr and "found 0 times" in res.stderr


def test_the_other_orb_slam2_recipes_still_patch_their_trees(tmp_path):
    """The family DynaSLAM shares (slamrun/methods/recipes/common) keeps ORB-SLAM2's and DF-ORB-SLAM's patches
    working."""
    for name in ("orb_slam2", "df_orb_slam"):
        root = unpack_upstream(name, tmp_path / name)
        res = subprocess.run(
            [sys.executable, str(recipe(name) / "patches.py"), str(root)], capture_output=True, text=True
        )
        assert res.returncode == 0, (name, res.stderr)


def test_the_python_packages_are_pinned_once_and_installed_by_hash():
    files = pypi_files_of(RECIPE / "Dockerfile")
    table = src.pypi_table(src.PY27_DYNASLAM)
    assert files == [f.filename for f in table]  # the Dockerfile copies exactly the pinned files
    assert all(src.PYPI_FILES[f.filename] == f for f in table)
    pins = [line for line in (RECIPE / "requirements-py27.txt").read_text().splitlines() if not line.startswith("#")]
    assert "\n".join(pins) + "\n" == src.requirements(list(table))
    versions = {f.project: f.version for f in table}
    assert versions["tensorflow-cpu"] == "1.15.0" and versions["keras"] == "2.1.6" and versions["numpy"] == "1.16.6"
    assert versions["scipy"] == "1.2.3"  # scipy.misc.imresize, which Mask R-CNN's utils.py calls, is gone in 1.3
    assert len(versions) == len(table)  # one file per project
    for f in table:  # Python 2.7 files only: CPython 2.7 wide-unicode wheels, universal wheels or sdists
        assert "-cp27-cp27mu-" in f.filename or "-py2" in f.filename or f.filename.endswith((".tar.gz", ".zip"))
    assert "--require-hashes" in (RECIPE / "Dockerfile").read_text()


def test_file_names_give_project_and_version():
    sdist = src.pypi_file("functools32-3.2.3-2.tar.gz", "0" * 64)
    assert (sdist.project, sdist.version) == ("functools32", "3.2.3-2")
    assert src.pypi_file("networkx-2.2.zip", "0" * 64).version == "2.2"
    wheel = src.pypi_file("Keras_Applications-1.0.8-py2.py3-none-any.whl", "0" * 64)
    assert (wheel.project, wheel.version) == ("keras-applications", "1.0.8")
    with pytest.raises(SourceError, match="not a wheel or sdist"):
        src.pypi_file("README.txt", "0" * 64)


def test_a_wheel_with_a_wrong_checksum_is_refused_naming_the_file(tmp_path):
    numpy = next(f for f in src.PYPI_FILES.values() if f.filename.startswith("numpy-1.16.6-cp27"))
    folder = tmp_path / "given"
    folder.mkdir()
    (folder / numpy.filename).write_bytes(b"not numpy")
    with pytest.raises(SourceError) as err:
        obtain_pypi(numpy.filename, sources_dir=folder, cache=tmp_path / "cache", index_url="http://127.0.0.1:9")
    msg = str(err.value)
    assert numpy.filename in msg and numpy.sha256 in msg and "numpy 1.16.6" in msg and "replace it" in msg


def test_a_missing_wheel_names_what_to_fetch(tmp_path):
    sdist = src.PYPI_FILES["absl-py-0.15.0.tar.gz"]
    with loopback_server({}) as (url, hits):  # an index that knows nothing (every address: 404)
        with pytest.raises(SourceError) as err:
            obtain_pypi(sdist.filename, sources_dir=tmp_path, cache=tmp_path / "cache", index_url=url)
    msg = str(err.value)
    assert sdist.filename in msg and "absl-py==0.15.0" in msg and "--sources DIR" in msg
    assert hits == ["/pypi/absl-py/0.15.0/json", "/pypi/absl-py/json"]
    assert not (tmp_path / "cache" / sdist.filename).exists()


def test_weights_are_given_or_a_stand_in_or_the_build_says_where_they_are_published(tmp_path):
    with pytest.raises(Exception, match=r"mask_rcnn_coco.h5.*--weights mask_rcnn_coco.h5=FILE.*matterport"):
        model_choice("dynaslam", BuildOptions())
    kind, detail = model_choice("dynaslam", BuildOptions(standin_model=True))
    assert kind == "standin" and "stand-in" in detail and "NOT the trained network" in detail
    assert model_choice("dynaslam", BuildOptions(weights={"mask_rcnn_coco.h5": tmp_path / "w.h5"}))[0] == "given"
    # the recipe's own step, run without the file: it names it and the release that publishes it
    inputs = tmp_path / "inputs"
    (inputs / "weights").mkdir(parents=True)
    res = subprocess.run(
        ["sh", str(RECIPE / "mask-model.sh"), "given", str(inputs), str(tmp_path / "tree"), ""],
        capture_output=True,
        text=True,
    )
    assert res.returncode == 1 and "mask_rcnn_coco.h5 is missing" in res.stderr
    assert "matterport/Mask_RCNN GitHub release v2.0" in res.stderr and "--standin-model" in res.stderr


def test_the_vocabulary_is_trained_when_the_archive_lacks_it():
    archive = require_upstream(UPSTREAM / src.SOURCES["dynaslam"].filename)
    assert vocabulary_choice("dynaslam", {"dynaslam": archive}, BuildOptions())[0] == "trained"
    with pytest.raises(Exception, match="--vocabulary dynaslam=FILE"):
        vocabulary_choice("dynaslam", {"dynaslam": archive}, BuildOptions(train_vocabulary=False))


def built_image():
    return images.built_image(IMAGE, "make images METHOD=dynaslam ARGS=--standin-model")


def test_python_2_7_loads_mask_rcnn_inside_the_image():
    """DynaSLAM's MaskRCNN.Mask, from the tree's root as mono_tum runs it, loads its weights and segments a frame
    under the image's Python 2.7, with no network, as the image's user."""
    api, labels = built_image()
    container = api.create_container(
        IMAGE,
        command=["python2.7", "check_mask_rcnn.py"],
        working_dir="/opt/DynaSLAM",
        environment={"MPLBACKEND": "Agg", "CUDA_VISIBLE_DEVICES": ""},
        host_config=api.create_host_config(network_mode="none"),
    )
    try:
        api.start(container)
        status = api.wait(container, timeout=600)["StatusCode"]
        out = api.logs(container).decode(errors="replace")
    finally:
        api.remove_container(container, force=True)
    assert status == 0, out[-3000:]
    assert "check_mask_rcnn: Mask R-CNN loads in" in out and "segments a 640x480 frame" in out
    version = api.create_container(IMAGE, command=["python2.7", "-c", "import tensorflow as t; print(t.__version__)"])
    try:
        api.start(version)
        api.wait(version, timeout=300)
        assert api.logs(version).decode().strip().splitlines()[-1] == "1.15.0"
    finally:
        api.remove_container(version, force=True)
    if "stand-in" in labels.get("slamrun.weights", ""):  # a stand-in says so in the image too
        txt = api.create_container(IMAGE, command=["cat", "/opt/DynaSLAM/src/python/mask_rcnn_coco.h5.txt"])
        try:
            api.start(txt)
            api.wait(txt, timeout=60)
            assert "NOT the COCO weights" in api.logs(txt).decode()
        finally:
            api.remove_container(txt, force=True)


def test_the_image_claims_no_gpu_and_says_which_network_it_holds():
    api, labels = built_image()
    env = (api.inspect_image(IMAGE).get("Config") or {}).get("Env") or []
    assert not any(e.startswith("NVIDIA_") for e in env)  # no GPU runtime asked for: TensorFlow's CPU build
    assert labels.get("slamrun.method") == "dynaslam" and "mask_rcnn_coco.h5" in labels.get("slamrun.weights", "")
    assert os.path.basename(IMAGE).startswith("dynaslam")


def test_its_verification_fits_in_half_an_hour_and_says_what_it_ran():
    from slamrun.images.verify import VerifyRow, markdown_table, scope_of

    scope = scope_of("dynaslam")
    seconds_per_frame = 10  # Mask R-CNN on this machine's 2 cores, the slower end measured (the README's row)
    runs = len(scope.sequences) * 2 * scope.trials  # forward and backward
    assert runs >= 2 and runs * (scope.frames * seconds_per_frame + 60) <= 36 * 60
    assert scope.timeout_s >= scope.frames * 2 * seconds_per_frame  # a run slowed twice by other work still ends
    row = VerifyRow("dynaslam", True, runs=runs, runs_ok=runs, scope=str(scope), plumbing_only=True)
    assert f"| {runs}/{runs} (room_a only, 1 trial, {scope.frames} frames: Mask R-CNN" in markdown_table([row])
