"""The ten study methods: configure, command and read_trajectory on real or format-exact outputs, and a
consistency check of registry, Docker folders, pinned commits and loop-closure switches."""

from __future__ import annotations

import ast
import importlib
import pkgutil
import re
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from pydantic import ValidationError

import slamrun.methods
from slamrun.datasets.view import Direction, PreparedView, Profile
from slamrun.errors import MethodFailure, TrajectoryFormatError
from slamrun.images.build import sources_of
from slamrun.images.sources import SOURCES
from slamrun.methods.base import Method
from tests.conftest import recipe

ROOT = Path(__file__).resolve().parents[1]
RECIPES = Path(slamrun.methods.__file__).parent / "recipes"
# upstream commits, as methods.md pins them
COMMITS = {
    "orb_slam2": "f2e6f51",
    "df_orb_slam": "462425d",
    "lsd_slam": "d1e6f0e",
    "dso": "7b0c99f",
    "svo": "d616106",
    "ldso": "9b0c48c",
    "dsm": "36ab5cf",
    "dynaslam": "8f894a8",
    "cnn_dso": "46562f0",
    "cnn_svo": "d5591ea",
}
STUDY_NO_LOOP = {"orb_slam2", "df_orb_slam", "dynaslam", "ldso", "dsm"}  # the study turned loop closure off


def make_view(root: Path, times: np.ndarray, profile: Profile, direction=Direction.forward) -> PreparedView:
    """A view folder whose frames carry the given (original) timestamps: enough for read_trajectory."""
    root.mkdir(parents=True, exist_ok=True)
    times = np.sort(times)
    t_view = times if direction is Direction.forward else (times[0] + times[-1] - times)[::-1]
    (root / "original_times.txt").write_text("".join(f"{float(t)!r}\n" for t in times))
    (root / "times.txt").write_text("".join(f"{i:06d} {t:.6f} 1.0\n" for i, t in enumerate(t_view)))
    pinhole = (320.0, 320.0, 319.5, 239.5) if profile is Profile.rectified else None
    return PreparedView(
        root, "seq", direction, profile, len(times), float(times[0]), float(times[-1]), 640, 480, pinhole
    )


@pytest.fixture
def views(tmp_path):
    t = 1000.0 + np.arange(200) / 30.0
    return {p: make_view(tmp_path / f"view_{p.value}", t, p) for p in Profile}


def instance(name: str, **params) -> Method:
    return slamrun.methods.get(name)(params)


# ---------------------------------------------------------------- configure and command


def test_orb_slam2_family_settings_parse_back(tmp_path, views):
    for name in ("orb_slam2", "df_orb_slam", "dynaslam"):
        m = instance(name, n_features=1500)
        files = m.configure(views[Profile.rectified], Path("/work"))
        path = tmp_path / f"{name}.yaml"
        path.write_text(files["settings.yaml"])
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
        assert fs.isOpened(), name
        assert fs.getNode("Camera.fx").real() == 320.0 and fs.getNode("Camera.cy").real() == 239.5
        assert fs.getNode("Camera.k1").real() == 0.0 and fs.getNode("Camera.RGB").real() == 0
        assert fs.getNode("Camera.fps").real() == pytest.approx(30.0)
        assert fs.getNode("ORBextractor.nFeatures").real() == 1500
        for key in ("ORBextractor.scaleFactor", "ORBextractor.nLevels", "Viewer.ViewpointF"):
            assert not fs.getNode(key).empty(), key
        argv = m.for_backend("docker").command(views[Profile.rectified].at("/data"), Path("/work"))
        assert argv[1].endswith("ORBvoc.txt") and argv[2] == "/work/settings.yaml" and argv[3] == "/data"
        assert m.environment()["ORB_SLAM2_NO_LOOP"] == "1"
        assert "ORB_SLAM2_NO_LOOP" not in instance(name, loop_closure=True).environment()
    dyna = instance("dynaslam")
    assert dyna.command(views[Profile.rectified].at("/data"), Path("/work"))[-1] == "/work/masks"
    assert instance("dynaslam", masks=False).command(views[Profile.rectified].at("/data"), Path("/work"))[-1] == "/data"
    assert dyna.environment()["CUDA_VISIBLE_DEVICES"] == "" and not dyna.needs_gpu
    with pytest.raises(ValidationError, match="gpu"):  # its image is CPU-only: a GPU is not claimed
        instance("dynaslam", gpu=True)


def test_dynaslam_refuses_other_sizes(tmp_path):
    view = make_view(tmp_path / "v", 1000.0 + np.arange(10) / 30, Profile.rectified)
    small = PreparedView(**{**view.__dict__, "width": 320, "height": 240})
    with pytest.raises(MethodFailure, match="640x480"):
        instance("dynaslam").configure(small, Path("/work"))


def test_dso_family_commands(views):
    v = views[Profile.native].at("/data")
    argv = instance("dso").command(v, Path("/work"))
    assert argv[0] == "/opt/dso/build/bin/dso_dataset"
    assert {
        "files=/data/images",
        "calib=/data/camera.txt",
        "gamma=/data/pcalib.txt",
        "vignette=/data/vignette.png",
        "mode=0",
        "preset=0",
        "nogui=1",
        "nolog=1",
        "quiet=1",
    } <= set(argv)
    assert "mode=1" in instance("dso", photometric=False).command(v, Path("/work"))
    assert "nomt=1" in instance("dso", single_thread=True).command(v, Path("/work"))
    cnn = instance("cnn_dso").command(v, Path("/work"))
    assert cnn[0].startswith("/opt/CNN-DSO") and any(a.startswith("cnn=") and a.endswith(".pb") for a in cnn)
    ldso = instance("ldso").command(v, Path("/work"))
    assert "loopclosing=0" in ldso and "output=/work/result.txt" in ldso and any(a.startswith("vocab=") for a in ldso)
    assert "loopclosing=1" in instance("ldso", loop_closure=True).command(v, Path("/work"))
    assert not any(a.startswith("reverse") for a in ldso + argv)  # backward comes from the mirror-time view


def test_svo_family_parameters_parse_back(views):
    # SVO: the native view's camera.txt (FOV = vikit's ATAN camera) and images.txt, read by svo_offline
    v = views[Profile.native].at("/data")
    m = instance("svo", max_fts=150)
    params = yaml.safe_load(m.configure(v, Path("/work"))["svo_params.yaml"])
    assert params["svo/cam_model"] == "ATAN" and params["svo/camera_file"] == "/data/camera.txt"
    assert params["svo/dataset_directory"] == "/data" and params["svo/output_file"] == "/work/traj_estimate.txt"
    assert params["svo/trace_dir"] == "/work" and params["svo/max_fts"] == 150
    assert params["svo/init_min_disparity"] == 10.0  # lower than SVO's 50 px: see slamrun/methods/svo/__init__.py
    assert m.command(v, Path("/work")) == ["/opt/svo/bin/svo_offline", "/work/svo_params.yaml"]
    assert m.accepts_exit(3, Path("/work")) and not m.accepts_exit(1, Path("/work"))  # 3: no pose written
    assert m.failure_from_log("slamrun: never initialised\n") == "not_initialized"
    # CNN-SVO: the rectified view's pinhole, a folder of frames and a one-column times file, vo_kitti defaults
    v = views[Profile.rectified].at("/data")
    cnn = instance("cnn_svo", max_fts=150).for_backend("docker")
    params = yaml.safe_load(cnn.configure(v, Path("/work"))["svo_params.yaml"])
    assert params["svo/cam_model"] == "Pinhole" and params["svo/cam_fx"] == 320.0 and params["svo/cam_width"] == 640
    assert params["svo/image_folder"] == "/data/images" and params["svo/times_file"] == "/data/times_single.txt"
    assert params["svo/output_file"] == "/work/traj_estimate_ATE.txt" and params["svo/frame_delay_ms"] == 50
    assert params["svo/cnn_model"].endswith("model_city2kitti.pb") and params["svo/max_fts"] == 150
    assert params["svo/quality_max_drop_fts"] == 150 and params["svo/use_motion_model"] is True  # vo_kitti.yaml
    assert instance("cnn_svo").params.max_fts == 200 and instance("cnn_svo").params.max_n_kfs == 0
    assert cnn.command(v, Path("/work")) == ["/opt/CNN-SVO/rpg_svo/svo/bin/cnn_svo_offline", "/work/svo_params.yaml"]
    assert cnn.environment() == {"CUDA_VISIBLE_DEVICES": ""} and cnn.accepts_exit(3, Path("/work"))


def test_dsm_files_parse_back(tmp_path, views):
    m = instance("dsm")
    files = m.configure(views[Profile.rectified].at("/data"), Path("/work"))
    (tmp_path / "calib.yaml").write_text(files["calib.yaml"])
    fs = cv2.FileStorage(str(tmp_path / "calib.yaml"), cv2.FILE_STORAGE_READ)
    assert fs.getNode("Camera.fx").real() == 320.0 and fs.getNode("Camera.width").real() == 640
    settings = dict(line.split(" = ") for line in files["settings.txt"].splitlines())
    assert settings["singleThreaded"] == "true" and settings["doOnlyTemporalOpt"] == "true"
    assert (
        instance("dsm", loop_closure=True)
        .configure(views[Profile.rectified], Path("/w"))["settings.txt"]
        .count("doOnlyTemporalOpt = false")
        == 1
    )
    argv = m.command(views[Profile.rectified].at("/data"), Path("/work"))
    assert argv[1:] == [
        "/work/calib.yaml",
        "/work/settings.txt",
        "/data/images",
        "/data/times.txt",
        "/work/dsm_trajectory.txt",
    ]


def test_lsd_slam_list_and_command(views):
    v = views[Profile.native].at("/data")
    m = instance("lsd_slam")
    files = m.configure(v, Path("/work"))
    lines = files["files.txt"].splitlines()
    assert len(lines) == 200 and lines[0] == "/data/images/000000.png" and lines[-1].endswith("000199.png")
    argv = m.command(v, Path("/work"))
    assert argv == [m.binary, "/work/files.txt", "/data/camera.txt", "/work/lsd_poses.txt", "0"]


# ---------------------------------------------------------------- read_trajectory


def real(shared_data: Path, name: str) -> Path:
    return shared_data / "study_trajectories" / name


@pytest.mark.parametrize(
    "method, output, source",
    [
        ("dso", "result.txt", "dso_bw__sequence_48_0.txt"),
        ("cnn_dso", "result.txt", "dso_bw__sequence_47_9.txt"),
        ("dsm", "dsm_trajectory.txt", "dsm_bw__sequence_47_6.txt"),
        ("cnn_svo", "results/CNN_VO/traj_estimate_ATE.txt", "cnn-svo_fw__sequence_48_8.txt"),
        ("dynaslam", "KeyFrameTrajectory.txt", "dyna_fw__sequence_49_2.txt"),
    ],
)
def test_read_real_outputs(tmp_path, shared_data, method, output, source):
    src = real(shared_data, source)
    raw = np.loadtxt(src)
    m = instance(method)
    view = make_view(tmp_path / "view", raw[:, 0], m.profile)
    work = tmp_path / "work"
    (work / output).parent.mkdir(parents=True)
    shutil.copy(src, work / output)
    traj = m.read_trajectory(work, view)
    assert len(traj) == len(np.unique(raw[:, 0])) and np.all(np.diff(traj.timestamps) > 0)
    np.testing.assert_array_equal(traj.timestamps, np.unique(raw[:, 0]))  # original timestamps, exactly
    np.testing.assert_allclose(np.linalg.norm(traj.quaternions, axis=1), 1.0)


def test_read_format_exact_outputs(tmp_path, views):
    t = views[Profile.rectified].original_timestamps()
    rng = np.random.default_rng(0)
    pos = rng.normal(size=(len(t), 3))
    q = rng.normal(size=(len(t), 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    # ORB-SLAM2 family: KeyFrameTrajectory.txt, 6-decimal timestamps, 7 values
    work = tmp_path / "orb"
    work.mkdir()
    rows = [
        f"{t[i]:.6f} {' '.join(f'{v:.7f}' for v in pos[i])} {' '.join(f'{v:.7f}' for v in q[i])}"
        for i in range(0, len(t), 5)
    ]
    (work / "KeyFrameTrajectory.txt").write_text("\n".join(rows) + "\n")
    for name in ("orb_slam2", "df_orb_slam"):
        traj = instance(name).read_trajectory(work, views[Profile.rectified])
        assert len(traj) == 40 and set(traj.timestamps) <= set(t)
    # SVO: traj_estimate.txt, TUM, every frame
    (work / "traj_estimate.txt").write_text(
        "".join(
            f"{t[i]:.6f} {pos[i][0]} {pos[i][1]} {pos[i][2]} {q[i][0]} {q[i][1]} {q[i][2]} {q[i][3]}\n"
            for i in range(len(t))
        )
    )
    assert len(instance("svo").read_trajectory(work, views[Profile.rectified])) == len(t)
    # LSD-SLAM: frame index + pose; the index maps to the view's frame time
    (work / "lsd_poses.txt").write_text(
        "".join(
            f"{i} {pos[i][0]} {pos[i][1]} {pos[i][2]} {q[i][0]} {q[i][1]} {q[i][2]} {q[i][3]}\n" for i in (0, 7, 42)
        )
    )
    traj = instance("lsd_slam").read_trajectory(work, views[Profile.native])
    np.testing.assert_array_equal(traj.timestamps, t[[0, 7, 42]])
    # CNN-SVO: the 3x4 file when the TUM one is missing
    cnn_dir = work / "results" / "CNN_VO"
    cnn_dir.mkdir(parents=True)
    R = cv2.Rodrigues(np.array([0.1, 0.2, 0.3]))[0]
    (cnn_dir / "traj_estimate.txt").write_text(
        "".join(
            f"{t[i]:.6f} " + " ".join(f"{v:.9f}" for v in np.hstack([R, pos[i][:, None]]).ravel()) + "\n"
            for i in range(10)
        )
    )
    traj = instance("cnn_svo").read_trajectory(work, views[Profile.rectified])
    assert len(traj) == 10 and np.allclose(traj.positions, pos[:10])


def test_backward_output_maps_to_original_time(tmp_path):
    t = 1000.0 + np.arange(50) / 30.0
    view = make_view(tmp_path / "v", t, Profile.native, Direction.backward)
    work = tmp_path / "w"
    work.mkdir()
    t_view = t[0] + t[-1] - t[::-1]
    (work / "result.txt").write_text("".join(f"{tv:.15g} {i} 0 0 0 0 0 1\n" for i, tv in enumerate(t_view)))
    traj = instance("dso").read_trajectory(work, view)
    np.testing.assert_array_equal(traj.timestamps, t)
    assert traj.positions[0, 0] == 49  # the last view frame is the first original frame


def test_failure_cases(tmp_path, views):
    work = tmp_path / "w"
    work.mkdir()
    v = views[Profile.native]
    with pytest.raises(MethodFailure) as err:
        instance("dso").read_trajectory(work, v)
    assert err.value.kind == "no_output"
    (work / "result.txt").write_text("")
    with pytest.raises(MethodFailure) as err:
        instance("dso").read_trajectory(work, v)
    assert err.value.kind == "not_initialized"
    (work / "result.txt").write_text("1000.0 1 2 3\n")
    with pytest.raises(TrajectoryFormatError, match="result.txt:1"):
        instance("dso").read_trajectory(work, v)
    (work / "lsd_poses.txt").write_text("999 0 0 0 0 0 0 1\n")
    with pytest.raises(MethodFailure, match="outside"):
        instance("lsd_slam").read_trajectory(work, v)
    # LDSO: exit 139 after writing counts, before writing it does not
    ldso = instance("ldso")
    (work / "result.txt").unlink()
    assert not ldso.accepts_exit(139, work)
    (work / "result.txt").write_text("1000.0 0 0 0 0 0 0 1\n")
    assert (
        ldso.accepts_exit(139, work) and not ldso.accepts_exit(1, work) and not instance("dso").accepts_exit(139, work)
    )
    # log lines
    assert instance("dso").failure_from_log("...\nINITIALIZATION FAILED\n") == "not_initialized"
    assert instance("dso").failure_from_log("LOST!\n") == "lost"
    assert instance("orb_slam2").failure_from_log("Track lost soon after initialisation, reseting...") == "lost"


def test_local_backend_needs_a_local_build(tiny_dataset, tmp_path):
    from slamrun.engine.spec_file import validate_spec
    from slamrun.errors import SpecError

    build = tmp_path / "mono_tum"  # a local build: a program that exists
    build.write_text("#!/bin/sh\n")
    build.chmod(0o755)
    raw = {
        "name": "x",
        "datasets": [{"name": "d", "path": str(tiny_dataset), "sequences": ["seq_a"]}],
        "methods": [{"name": "dso"}, {"name": "orb_slam2", "params": {"executable": str(build)}}],
    }
    with pytest.raises(SpecError) as err:
        validate_spec(raw, tmp_path)
    assert "methods[0]: dso runs natively only from a local build" in str(err.value)
    assert "methods[1]" not in str(err.value)
    assert validate_spec({**raw, "backend": "docker"}, tmp_path)
    raw["methods"][1]["params"]["executable"] = "/opt/orb/mono_tum"  # not here: refused before any run
    with pytest.raises(SpecError, match="methods\\[1\\]: orb_slam2: params.executable: /opt/orb/mono_tum not found"):
        validate_spec(raw, tmp_path)
    assert (
        instance("orb_slam2", executable="/opt/orb/mono_tum")
        .for_backend("local")
        .command(
            PreparedView(Path("/v"), "s", Direction.forward, Profile.rectified, 2, 0.0, 1.0, 640, 480, (1, 1, 1, 1)),
            Path("/w"),
        )[0]
        == "/opt/orb/mono_tum"
    )


# ---------------------------------------------------------------- consistency


def test_every_module_is_registered_and_every_image_has_a_folder():
    classes = set()
    for mod in pkgutil.walk_packages(slamrun.methods.__path__, "slamrun.methods."):
        if mod.name.endswith("__main__") or mod.name.endswith("sfm_process"):
            continue
        module = importlib.import_module(mod.name)
        for obj in vars(module).values():
            if (
                isinstance(obj, type)
                and issubclass(obj, Method)
                and obj.__module__ == module.__name__
                and getattr(obj, "name", None)
            ):
                classes.add(obj)
    assert classes == set(slamrun.methods.REGISTRY.values())
    for name, cls in slamrun.methods.REGISTRY.items():
        assert cls.native or cls.recipe().exists(), name


@pytest.mark.parametrize("name", sorted(COMMITS))
def test_dockerfile_pins_commit_and_portable_flags(name):
    docker = recipe(name)
    text = (docker / "Dockerfile").read_text()
    if name in sources_of(docker / "Dockerfile"):  # the source by its pinned commit, from the build context
        assert SOURCES[name].commit.startswith(COMMITS[name])
    else:  # not ported to the sources path yet: cloned at the pinned commit
        var = name.upper()
        assert re.search(rf"^ARG {var}_REPO=https://github\.com/", text, re.M), f"{name}: no ARG {var}_REPO"
        assert re.search(rf"^ARG {var}_COMMIT={COMMITS[name]}\s*$", text, re.M), f"{name}: commit not pinned"
    # every upstream CMakeLists says -march=native: replaced by portable-march.sh, itself or through prepare-source.sh
    assert "portable-march.sh" in text or "prepare-source.sh" in text
    assert "portable-march.sh" in (RECIPES / "common" / "prepare-source.sh").read_text()
    for f in docker.rglob("*"):
        if f.is_file():
            assert "-march=native" not in f.read_text(errors="ignore").replace("s/-march=native", ""), f
    assert "USER slam" in text  # non-root


def test_commits_match_methods_md():
    doc = ROOT.parent / "shared" / "docs" / "methods.md"
    if not doc.exists():
        pytest.skip(reason="shared/docs/methods.md not beside the repository")
    text = doc.read_text()
    for name, commit in COMMITS.items():
        assert f"@ {commit}" in text, name


@pytest.mark.parametrize("name", sorted(COMMITS))
def test_loop_closure_switch_where_the_study_used_one(name):
    cls = slamrun.methods.get(name)
    if name in STUDY_NO_LOOP:
        assert cls.loop_closure_switch, name
        assert cls.Params().loop_closure is False  # off by default, as in the study


def test_paper_spec_is_the_full_study():
    from slamrun.engine.plan import plan
    from slamrun.engine.spec_file import load_spec

    spec = load_spec(ROOT / "configs" / "paper.yaml", check_files=False)
    runs = plan(spec)
    assert len(runs) == 10 * 50 * 2 * 10 and {m.name for m in spec.methods} == set(COMMITS)
    timing = load_spec(ROOT / "configs" / "paper-timing.yaml", check_files=False)
    assert timing.measurement == "exclusive" and len(plan(timing)) == 100
    assert timing.datasets[0].sequences == ["sequence_01"]


# the study's loop-closure settings (shared/docs/study.md), for the methods that have a switch
STUDY_LOOP_CLOSURE = {
    "orb_slam2": False,
    "df_orb_slam": False,
    "dynaslam": False,
    "ldso": False,
    "dsm": False,
    "lsd_slam": True,
}


def test_paper_spec_turns_loop_closure_off_where_the_study_did():
    """The study disabled loop closure in ORB-SLAM2, DF-ORB-SLAM, DynaSLAM, LDSO and DSM only (shared/docs/
    study.md); LSD-SLAM ran with its own default, global mapping on (`_doSLAM` true), so the paper spec asks
    for it. slamrun's own default stays off for every method that has a switch."""
    from slamrun.engine.spec_file import load_spec

    for name in ("paper.yaml", "paper-timing.yaml"):
        spec = load_spec(ROOT / "configs" / name, check_files=False)
        built = [slamrun.methods.get(m.name)(m.params) for m in spec.methods]
        closing = {m.name: m.params.loop_closure for m in built if m.loop_closure_switch}
        assert closing == STUDY_LOOP_CLOSURE, name
    assert not slamrun.methods.get("lsd_slam")({}).params.loop_closure


def test_pure_modules_import_in_one_direction():
    """Trajectory, alignment, evaluation and statistics never import the scheduler, Docker or the CLI."""
    banned = ("slamrun.engine.scheduler", "slamrun.backends", "slamrun.cli", "slamrun.engine.campaign", "docker")
    for rel in (
        "slamrun/core/trajectory.py",
        "slamrun/core/alignment.py",
        "slamrun/core/evaluation.py",
        "slamrun/analysis/stats.py",
        "slamrun/core/camera.py",
    ):
        tree = ast.parse((ROOT / rel).read_text())
        for node in ast.walk(tree):
            names = (
                [a.name for a in node.names]
                if isinstance(node, ast.Import)
                else [node.module or ""]
                if isinstance(node, ast.ImportFrom)
                else []
            )
            for n in names:
                assert not n.startswith(banned), f"{rel} imports {n}"


def test_df_orb_slam_monocular_pose_switch_and_orb_slam2_recoverable_reset():
    env = instance("df_orb_slam").environment()
    assert env["DF_ORB_SLAM_MONO_POSE"] == "orb" and env["ORB_SLAM2_NO_LOOP"] == "1"
    assert "DF_ORB_SLAM_MONO_POSE" not in instance("df_orb_slam", mono_pose="em").environment()
    orb = instance("orb_slam2")
    reset_then_new_map = (
        "New Map created with 120 points\nTrack lost soon after initialisation, reseting...\n"
        "System Reseting\nNew Map created with 98 points\nmedian tracking time: 0.02\n"
    )
    assert orb.failure_from_log(reset_then_new_map) is None  # re-initialised: not lost
    assert orb.failure_from_log("New Map created with 120 points\nTrack lost soon after initialisation, reseting...\n")


def test_list_methods_names_every_method():
    """`slamrun list-methods` prints every registered method, the external one (whose image comes from the
    spec) included."""
    import subprocess
    import sys

    import slamrun.methods

    out = subprocess.run(
        [sys.executable, "-m", "slamrun.cli", "list-methods"], capture_output=True, text=True, env={"COLUMNS": "200"}
    )
    assert out.returncode == 0, out.stderr
    for name in slamrun.methods.REGISTRY:
        assert name in out.stdout
