"""SVO and LSD-SLAM without ROS: the patch scripts on the real upstream trees (shared/upstream), the offline
drivers' contracts checked against those trees (parameter names, the ROS node's settings, the core source list),
and the adapters' conversion of real outputs written by the built images (tests/fixtures/svo, lsd_slam: a run
forward and a run backward on the first 50 frames of the verification's room_b, with the small files of the
views they ran on)."""

from __future__ import annotations

import ast
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

import slamrun.methods
from slamrun.datasets.view import Direction, PreparedView
from tests.conftest import recipe, unpack_upstream

ROOT = Path(__file__).resolve().parents[1]
FIXTURES = Path(__file__).parent / "fixtures"
GET_PARAM = re.compile(r'getParam<[^>]*>\("(svo/\w+)"')


def run(script: Path, *args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(script), *map(str, args)], capture_output=True, text=True)


def svo_trees(tmp_path: Path) -> tuple[Path, Path, Path, Path]:
    return tuple(unpack_upstream(name, tmp_path) for name in ("svo", "rpg_vikit", "fast", "sophus"))


# ---------------------------------------------------------------- SVO


def test_svo_patches_on_the_real_trees(tmp_path):
    svo, vikit, fast, sophus = svo_trees(tmp_path)
    res = run(recipe("svo") / "patches.py", svo, vikit, fast, sophus)
    assert res.returncode == 0, res.stderr
    cm = (svo / "svo/CMakeLists.txt").read_text()
    assert "SET(USE_ROS FALSE)" in cm and "ADD_DEFINITIONS(-DSLAMRUN_PARAMS)" in cm
    assert cm.index("INCLUDE_DIRECTORIES(BEFORE ${SLAMRUN_INCLUDE_DIR})") < cm.index("${vikit_common_INCLUDE_DIRS}")
    assert "ADD_EXECUTABLE(svo_offline ${SLAMRUN_SVO_DRIVER})" in cm and "test_pipeline" not in cm
    config = (svo / "svo/src/config.cpp").read_text()
    assert config.count("#if defined(SVO_USE_ROS) || defined(SLAMRUN_PARAMS)") == 2  # the include and getParam
    assert "using namespace boost::placeholders;" in (svo / "svo/include/svo/global.h").read_text()
    for f in (svo / "svo/src/sparse_img_align.cpp", vikit / "vikit_common/src/img_align.cpp"):
        assert "cv::imshow" not in f.read_text() and "namedWindow" not in f.read_text(), f
    assert "SET(USE_ROS FALSE)" in (vikit / "vikit_common/CMakeLists.txt").read_text()
    vikit_src = "".join(p.read_text() for p in (vikit / "vikit_common/src").glob("*.cpp"))
    assert "CV_RANSAC" not in vikit_src and "CV_INTER_LINEAR" not in vikit_src
    fast_cm = (fast / "CMakeLists.txt").read_text()
    assert "SET(BUILD_TEST FALSE)" in fast_cm and '"-std=c++11 -Wall -Werror' in fast_cm
    assert "unit_complex_ = std::complex<double>(1, 0);" in (sophus / "sophus/so2.cpp").read_text()
    # a second run on the patched trees fails instead of patching twice
    assert run(recipe("svo") / "patches.py", svo, vikit, fast, sophus).returncode != 0


def test_svo_atan_camera_centre_is_the_models_limit(tmp_path):
    """vikit's ATAN (FOV) camera returned a factor of 1 near the principal point, where the model's factors are
    t/s (distort) and s/t (undistort), t = 2 tan(s/2): the patched branches return exactly those limits."""
    trees = svo_trees(tmp_path)
    assert run(recipe("svo") / "patches.py", *trees).returncode == 0
    header = (trees[1] / "vikit_common/include/vikit/atan_camera.h").read_text()
    source = (trees[1] / "vikit_common/src/atan_camera.cpp").read_text()
    assert "if(r < 0.001)  // slamrun: the limit, not 1\n      return s_inv_ * tans_;" in header
    assert "d_factor = (s_ == 0.0) ? 1.0 : s_ * tans_inv_;" in source
    s = 0.8  # the synthetic sequences' omega
    t = 2 * np.tan(s / 2)
    for r in (1e-3, 1e-4):  # the model near the centre agrees with the limits the patch returns
        assert np.arctan(r * t) / (s * r) == pytest.approx(t / s, rel=1e-5)
        assert np.tan(r * s) / (t * r) == pytest.approx(s / t, rel=1e-5)
    assert abs(s / t - 1) > 0.05  # what upstream's `1.0` was off by


def test_svo_parameters_are_read_by_the_real_tree_and_the_driver(tmp_path, tmp_path_factory):
    """Every key the adapters write is one SVO's config (the ROS node's getParam calls) or the driver reads."""
    svo = unpack_upstream("svo", tmp_path)
    read = set(GET_PARAM.findall((svo / "svo/src/config.cpp").read_text()))
    read |= set(GET_PARAM.findall((recipe("svo") / "svo_offline.cpp").read_text()))
    view = PreparedView(
        Path("/data"), "s", Direction.forward, slamrun.methods.get("svo").profile, 10, 1.0, 1.3, 640, 480, None
    )
    params = yaml.safe_load(slamrun.methods.get("svo")({}).configure(view, Path("/work"))["svo_params.yaml"])
    assert set(params) <= read, set(params) - read
    assert {"svo/init_min_disparity", "svo/max_fts", "svo/grid_size"} <= set(params)
    cnn = unpack_upstream("cnn_svo", tmp_path_factory.mktemp("cnn"))
    read = set(GET_PARAM.findall((recipe("cnn_svo") / "cnn_svo_offline.cpp").read_text()))
    for f in (cnn / "rpg_svo/svo/src").glob("*.cpp"):
        read |= set(GET_PARAM.findall(f.read_text(errors="ignore")))
    profile = slamrun.methods.get("cnn_svo").profile
    rect = PreparedView(
        Path("/data"), "s", Direction.forward, profile, 10, 1.0, 1.3, 640, 480, (320.0, 320.0, 319.5, 239.5)
    )
    params = yaml.safe_load(slamrun.methods.get("cnn_svo")({}).configure(rect, Path("/work"))["svo_params.yaml"])
    assert set(params) <= read, set(params) - read
    # the authors' vo_kitti.yaml: every setting (not its paths or the viewer's marker sizes), with its value
    kitti = yaml.safe_load((cnn / "rpg_svo/svo_ros/param/vo_kitti.yaml").read_text())
    settings = {k: v for k, v in kitti.items() if not isinstance(v, str) and not k.endswith("_marker_scale")}
    assert {f"svo/{k}": v for k, v in settings.items()} == {f"svo/{k}": params[f"svo/{k}"] for k in settings}


def test_the_svo_driver_restarts_a_paused_system():
    """svo_offline restarts SVO when an initialisation failure paused it, and exits 3 without a pose."""
    driver = (recipe("svo") / "svo_offline.cpp").read_text()
    loop = driver[driver.index("vo->addImage(img, frames[i].t);") :]
    assert loop.index("STAGE_PAUSED") < loop.index("vo->start();")
    assert "return n_poses > 0 ? 0 : 3;" in driver
    assert slamrun.methods.get("svo").no_pose_exit == 3


# ---------------------------------------------------------------- LSD-SLAM


def test_lsd_slam_patches_on_the_real_tree(tmp_path):
    root = unpack_upstream("lsd_slam", tmp_path)
    res = run(recipe("lsd_slam") / "patches.py", root)
    assert res.returncode == 0, res.stderr
    src = root / "lsd_slam_core/src"
    itr = (src / "util/IndexThreadReduce.h").read_text()
    assert itr.index('#include "boost/thread.hpp"') < itr.index("using namespace boost::placeholders;")
    assert "std::pair<Frame* const,Sim3>" in (src / "DataStructures/Frame.h").read_text()
    assert "std::pair<Frame* const, Sim3>" in (src / "SlamSystem.cpp").read_text()
    assert (
        "aligned_allocator<KFConstraintStruct*> > newEdgeBuffer" in (src / "GlobalMapping/KeyFrameGraph.h").read_text()
    )
    core = "".join(p.read_text() for p in src.rglob("*.[ch]*") if "ROS" not in p.parts)
    assert "cvPoint(" not in core and not re.search(r"\bCV_(GRAY2RGB|LOAD_IMAGE_\w+|AA)\b", core)
    assert run(recipe("lsd_slam") / "patches.py", root).returncode != 0  # anchors: never patched twice


def cmake_list(text: str, var: str) -> list[str]:
    """The files of a CMake `set(VAR ...)`, relative to lsd_slam_core/src (other variables left out)."""
    body = re.search(rf"set\({var}\s(.*?)\)", text, re.S | re.I).group(1)
    words = [w.removeprefix("${PROJECT_SOURCE_DIR}/src/") for w in body.split()]
    return [w for w in words if not w.startswith("$")]


def test_lsd_slam_core_sources_are_upstreams(tmp_path):
    """The project's CMakeLists compiles exactly upstream's lsd_SOURCE_FILES, and a headless ImageDisplay in
    place of the OpenCV one (IOWrapper/ROS is left out)."""
    root = unpack_upstream("lsd_slam", tmp_path)
    upstream = (root / "lsd_slam_core/CMakeLists.txt").read_text()
    ours = (recipe("lsd_slam") / "CMakeLists.txt").read_text()
    assert sorted(cmake_list(ours, "LSD_CORE_SOURCES")) == sorted(cmake_list(upstream, "lsd_SOURCE_FILES"))
    extra = set(cmake_list(upstream, "SOURCE_FILES")) - set(cmake_list(upstream, "lsd_SOURCE_FILES"))
    assert extra == {
        "IOWrapper/ROS/ROSImageStreamThread.cpp",
        "IOWrapper/ROS/ROSOutput3DWrapper.cpp",
        "IOWrapper/OpenCV/ImageDisplay_OpenCV.cpp",
    }
    declared = re.findall(
        r"^\s*(?:void|int)\s+(\w+)\(", (root / "lsd_slam_core/src/IOWrapper/ImageDisplay.h").read_text(), re.M
    )
    headless = (recipe("lsd_slam") / "image_display_headless.cpp").read_text()
    assert set(declared) == {"displayImage", "waitKey", "waitKeyNoConsume", "closeAllWindows"}
    for name in declared:
        assert re.search(rf"\b(void|int) {name}\(", headless), name


def test_the_lsd_slam_driver_uses_the_ros_nodes_settings(tmp_path):
    """The ROS node's dynamic_reconfigure defaults (cfg/LSDParams.cfg) replace settings.cpp's values at start
    (dynConfCb); the driver sets the same values."""
    root = unpack_upstream("lsd_slam", tmp_path)
    cfg = (root / "lsd_slam_core/cfg/LSDParams.cfg").read_text()
    defaults = {}
    for call in re.findall(r"^gen\.add\((.*)\)\s*$", cfg, re.M):
        args = ast.literal_eval(
            f"[{call.replace('bool_t', 'None').replace('double_t', 'None').replace('int_t', 'None')}]"
        )
        defaults[args[0]] = args[4]
    driver = (recipe("lsd_slam") / "lsd_slam_offline.cpp").read_text()
    body = driver[driver.index("void ros_node_settings(bool loop) {") :]
    body = body[: body.index("\n}\n")]
    assigned = dict(re.findall(r"^\s*(\w+) = ([^;]+);", body, re.M))
    callback = (root / "lsd_slam_core/src/IOWrapper/ROS/rosReconfigure.h").read_text()
    for name, value in defaults.items():
        target = re.search(rf"(\w+) = config\.{name}(?:\*config\.{name})?;", callback)
        assert target, name
        var = target.group(1)
        if name == "doSLAM":
            assert assigned[var] == "loop"  # the LOOP argument (the study: 0, as _doSLAM:=false)
        elif name == "cameraPixelNoise":
            assert eval(assigned[var].replace(" ", "")) == value * value  # noqa: S307
        elif isinstance(value, bool):
            assert assigned[var] == str(value).lower(), name
        else:
            assert float(assigned[var]) == value, name
    assert assigned["KFUsageWeight"] == "4" and assigned["KFDistWeight"] == "3"  # settings.cpp: 3 and 4
    assert assigned["useAffineLightningEstimation"] == "false" and assigned["displayDepthMap"] == "false"
    # sequential (the node's _hz:=0) and no finalize() without the global mapping threads
    assert "system->trackFrame(image.data, i, true, t);" in driver and "if (loop) system->finalize();" in driver


# ---------------------------------------------------------------- real outputs of the built images


def fixture_run(method: str, direction: str) -> tuple[PreparedView, Path]:
    folder = FIXTURES / method / direction
    assert (folder / "view.json").exists(), f"{folder}: the fixture (a real output of the built image) is missing"
    return PreparedView.load(folder), folder


def expected_original_times(view: PreparedView, t_view: np.ndarray) -> np.ndarray:
    """The original frame timestamps of view times (independently of to_original: nearest original frame of the
    mirrored time)."""
    originals = view.original_timestamps()
    t = t_view if view.direction is Direction.forward else view.t_first + view.t_last - t_view
    nearest = np.abs(originals[None, :] - t[:, None]).argmin(axis=1)
    assert np.abs(originals[nearest] - t).max() < 1e-5  # the files' 6-decimal times
    return originals[nearest]


@pytest.mark.parametrize("direction", ["forward", "backward"])
def test_svo_output_of_the_built_image(direction):
    view, folder = fixture_run("svo", direction)
    raw = np.loadtxt(folder / "traj_estimate.txt", ndmin=2)
    assert 20 <= len(raw) <= view.n_frames and np.all(np.diff(raw[:, 0]) > 0)  # view time increases
    traj = slamrun.methods.get("svo")({}).read_trajectory(folder, view)
    expected = expected_original_times(view, raw[:, 0])
    np.testing.assert_array_equal(np.sort(expected), traj.timestamps)  # the original timestamps, exactly
    assert set(traj.timestamps) <= set(view.original_timestamps())
    order = np.argsort(expected)
    np.testing.assert_allclose(traj.positions, raw[order, 1:4])
    np.testing.assert_allclose(np.linalg.norm(traj.quaternions, axis=1), 1.0, atol=1e-6)
    # the first pose written is the map's origin (the first keyframe of the initialisation: identity)
    np.testing.assert_allclose(raw[0, 1:], [0, 0, 0, 0, 0, 0, 1], atol=1e-9)
    # view frame k is original frame k forward, n-1-k backward
    k = np.abs(view.view_timestamps()[:, None] - raw[None, :, 0]).argmin(axis=0)
    frame = k if direction == "forward" else view.n_frames - 1 - k
    np.testing.assert_array_equal(expected, view.original_timestamps()[frame])


@pytest.mark.parametrize("direction", ["forward", "backward"])
def test_lsd_slam_output_of_the_built_image(direction):
    view, folder = fixture_run("lsd_slam", direction)
    raw = np.loadtxt(folder / "lsd_poses.txt", ndmin=2)
    index = raw[:, 0].astype(int)
    assert index[0] == 0 and np.all(np.diff(index) > 0) and len(raw) >= 20  # frame 0 included
    np.testing.assert_allclose(raw[0, 1:], [0, 0, 0, 0, 0, 0, 1], atol=1e-9)  # the world's origin
    traj = slamrun.methods.get("lsd_slam")({}).read_trajectory(folder, view)
    originals = view.original_timestamps()
    expected = originals[index] if direction == "forward" else originals[view.n_frames - 1 - index]
    np.testing.assert_array_equal(np.sort(expected), traj.timestamps)  # exact original timestamps
    order = np.argsort(expected)
    np.testing.assert_allclose(traj.positions, raw[order, 1:4])
    if direction == "backward":
        assert traj.timestamps[-1] == originals[-1]  # view frame 0 is the sequence's last frame
