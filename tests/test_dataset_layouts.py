"""Datasets beyond TUM-Mono: EuRoC, KITTI odometry, TUM RGB-D and TUM-VI read into the same prepared views.

Each reader runs end to end on a synthetic sequence in its layout (with that layout's quirks), and against the real
ground-truth files of ../shared/data/evo_test_data where the layout has them; bad input is named with its file.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation

from slamrun.core import metrics
from slamrun.core.trajectory import read_euroc_csv, read_kitti, read_times, read_tum, write_tum
from slamrun.datasets.cache import prepare
from slamrun.datasets.euroc import EUROC_T_BS, read_sensor_yaml
from slamrun.datasets.kitti import drive
from slamrun.datasets.layouts import detect, open_sequence, sequence_identity
from slamrun.datasets.make_synthetic import generate
from slamrun.datasets.synth import Synth, camera_path
from slamrun.datasets.view import Direction, Profile
from slamrun.errors import DatasetError

FRAMES = 90
SEED = 4  # a loop every layout's reference_vo and colmap (every 3rd frame) track in 90 frames
NAMES = {"euroc": "V1_synth", "kitti": "00", "tum-rgbd": "rgbd_dataset_freiburg1_synth", "tum-vi": "room_synth"}


@pytest.fixture(scope="module")
def layouts(tmp_path_factory) -> dict[str, Path]:
    """One synthetic sequence per layout (KITTI's under sequences/ with poses/ beside it)."""
    root = tmp_path_factory.mktemp("layouts")
    out = {}
    for layout, name in NAMES.items():
        parent = root / layout / ("sequences" if layout == "kitti" else "")
        out[layout] = generate(parent / name, frames=FRAMES, seed=SEED, layout=layout)
    return out


def true_poses(layout: str) -> np.ndarray:
    """The synthetic camera-to-world poses at the frames (KITTI: relative to the first camera)."""
    synth = Synth(FRAMES, SEED, (640, 480), "indoor", NAMES[layout])
    synth = drive(synth) if layout == "kitti" else synth  # KITTI: a drive, outdoors
    rots, pos = camera_path(synth.scene, FRAMES, synth.laps)
    t = np.tile(np.eye(4), (FRAMES, 1, 1))
    t[:, :3, :3], t[:, :3, 3] = rots, pos
    return np.linalg.inv(t[0]) @ t if layout == "kitti" else t


@pytest.mark.parametrize("layout", sorted(NAMES))
def test_each_reader_gives_the_frames_times_camera_and_ground_truth_of_its_layout(layouts, layout):
    seq = open_sequence(layouts[layout])
    assert detect(seq.root) == layout and seq.layout == layout and seq.n_frames == FRAMES
    assert np.all(np.diff(seq.timestamps) > 0)
    gt = seq.groundtruth()
    truth = true_poses(layout)
    have = np.isfinite(gt.positions).all(axis=1)
    pos_err = np.linalg.norm(gt.positions[have] - truth[have, :3, 3], axis=1)
    rot_err = (Rotation.from_quat(gt.quaternions[have]).inv() * Rotation.from_matrix(truth[have, :3, :3])).magnitude()
    if layout == "tum-rgbd":
        # the nearest motion-capture pose within 0.02 s, as TUM's tools associate: off by the motion in <= 5 ms
        speed = np.linalg.norm(np.diff(truth[:, :3, 3], axis=0), axis=1).max() / np.diff(seq.timestamps).min()
        assert have.all() and pos_err.max() <= speed * 0.0051
    else:  # interpolated (EuRoC 200 Hz, TUM-VI 120 Hz, body to camera through T_BS / T_cam_imu) or exact (KITTI)
        assert pos_err.max() < 1e-4 and np.degrees(rot_err.max()) < 0.01
    if layout == "tum-vi":  # the motion-capture room sees the start and the end only: said, and evaluated there
        assert 0.3 < have.mean() < 0.5 and seq.notes
    else:
        assert have.all()
    # the prepared views: rectified pinhole frames at the original times, both directions
    for direction in Direction:
        view = prepare(seq.root, direction, Profile.rectified, layouts[layout].parent / f".cache-{layout}")
        assert view.n_frames == FRAMES and view.pinhole is not None
        assert np.array_equal(view.original_timestamps(), seq.timestamps)
        native = prepare(seq.root, direction, Profile.native, layouts[layout].parent / f".cache-{layout}")
        assert not native.photometric  # none of these datasets has a photometric calibration


def test_euroc_nanoseconds_and_the_camera_extrinsics(layouts):
    seq = open_sequence(layouts["euroc"])
    csv = (layouts["euroc"] / "mav0/cam0/data.csv").read_text().splitlines()[1:]
    ns = [int(line.split(",")[0]) for line in csv]
    assert seq.timestamps[0] == ns[0] // 10**9 + (ns[0] % 10**9) * 1e-9  # no float rounding of 19-digit stamps
    _, t_bs = read_sensor_yaml(layouts["euroc"] / "mav0/cam0/sensor.yaml")
    assert np.allclose(t_bs, EUROC_T_BS)


def tum_mono_copy(seq_dir: Path, cache: Path, dest: Path) -> Path:
    """The same sequence in the TUM-Mono layout: its rectified frames, their pinhole camera.txt (no further
    rectification), the original times and the reader's ground truth at the frames."""
    seq = open_sequence(seq_dir)
    view = prepare(seq_dir, Direction.forward, Profile.rectified, cache)
    dest.mkdir(parents=True)
    shutil.copytree(view.path(view.images_dir), dest / "images")
    for p in (dest / "images").iterdir():
        os.chmod(p, 0o644)
    os.chmod(dest / "images", 0o755)
    (dest / "camera.txt").write_text(view.path(view.camera).read_text())
    (dest / "times.txt").write_text("".join(f"{i:05d} {t!r}\n" for i, t in enumerate(seq.timestamps.tolist())))
    (dest / "pcalib.txt").write_text(" ".join(str(v) for v in range(256)) + "\n")
    cv2.imwrite(str(dest / "vignette.png"), np.full((view.height, view.width), 65535, np.uint16))
    write_tum(dest / "groundtruthSync.txt", seq.groundtruth())
    return dest


def test_each_layout_end_to_end_equals_the_same_sequence_in_tum_mono_layout(layouts, tmp_path):
    """A campaign with reference_vo (forward and backward) on every layout and on the same sequence written in the
    TUM-Mono layout, and one with colmap (forward) on EuRoC's (the layout whose frames are rectified from a distorted
    camera) and its copy: every run done and evaluated, and each method's metrics equal. (reference_vo's equality to
    1e-9 in both directions says the views are the same, whichever method reads them; colmap backward is tested in
    test_native_methods.py.)"""
    from slamrun.engine.campaign import run_campaign
    from slamrun.engine.spec_file import load_spec
    from tests.conftest import write_spec

    datasets = []
    for layout, seq_dir in layouts.items():
        copy = tum_mono_copy(seq_dir, tmp_path / "copy-cache", tmp_path / "tum-mono" / f"{layout}_{seq_dir.name}")
        half_s = {"delta": 0.5, "unit": "s"}  # RPE: colmap's every 3rd frame at 10, 20 and 30 Hz has pairs
        datasets.append(
            {"name": layout, "path": str(seq_dir.parent), "sequences": [seq_dir.name], "layout": layout, "rpe": half_s}
        )
        datasets.append(
            {
                "name": f"{layout}-as-tum-mono",
                "path": str(copy.parent),
                "sequences": [copy.name],
                "metrics": ["ate", "rpe"],
                "rpe": half_s,
            }
        )
    colmap = {
        "name": "colmap",
        "params": {"stride": 3, "max_features": 600, "overlap": 4, "max_image_size": 480},
        "directions": ["forward"],
    }
    frames = []
    for name, methods, sets in (
        ("vo", [{"name": "reference_vo"}], datasets),
        ("colmap", [colmap], [d for d in datasets if d["name"].startswith("euroc")]),
    ):
        (tmp_path / name).mkdir()
        spec = write_spec(
            tmp_path / name, tmp_path, methods, datasets=sets, trials=1, timeout_s=300, cache=str(tmp_path / "cache")
        )
        res = run_campaign(load_spec(spec), on_event=None)
        frames.append(pd.read_csv(res.results_csv))
    df = pd.concat(frames, ignore_index=True)
    assert len(df) == 2 * 2 * len(layouts) + 2
    assert df.status.eq("done").all(), df[["method", "dataset", "direction", "status", "message"]]
    assert df.eval_status.eq("ok").all() and df.ate_rmse.notna().all() and df.rpe_t_rmse.notna().all()
    kitti_rows = df[df.dataset == "kitti"]
    assert kitti_rows.columns.str.startswith("kitti_").any()  # KITTI's default metrics include its segments
    by_run = df.set_index(["method", "dataset", "direction"])
    for method, names, directions in (
        ("reference_vo", layouts, ("forward", "backward")),
        ("colmap", ["euroc"], ("forward",)),
    ):
        for layout in names:
            for direction in directions:
                a = by_run.loc[(method, layout, direction)]
                b = by_run.loc[(method, f"{layout}-as-tum-mono", direction)]
                # colmap's bundle adjustment sums on threads (Ceres), in an order that varies: equal to 1e-6
                rel = 1e-9 if method == "reference_vo" else 1e-6
                assert a.ate_rmse == pytest.approx(b.ate_rmse, rel=rel, abs=1e-12), (method, layout, direction)
                assert a.rpe_t_rmse == pytest.approx(b.rpe_t_rmse, rel=rel, abs=1e-12), (method, layout, direction)
    for layout in layouts:  # reference_vo within 1 % of the path's length (KITTI's: the courtyard's, 5 times longer)
        length = np.linalg.norm(np.diff(true_poses(layout)[:, :3, 3], axis=0), axis=1).sum()
        vo = df[(df.method == "reference_vo") & df.dataset.str.startswith(layout)]
        assert (vo.ate_rmse < 0.01 * length).all(), (layout, length, vo.ate_rmse.tolist())


# ---------------------------------------------------------------- the real ground-truth files of evo_test_data


def frames(folder: Path, names: list[str], size: tuple[int, int]) -> None:
    """Frame files for a reader test: one real PNG of the camera's size, hard-linked under every name."""
    folder.mkdir(parents=True, exist_ok=True)
    first = folder / names[0]
    first.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(first), np.full((size[1], size[0]), 128, np.uint8))
    for name in names[1:]:
        os.link(first, folder / name)


EUROC_SENSOR = """sensor_type: camera
T_BS:
  cols: 4
  rows: 4
  data: [0.0148655429818, -0.999880929698, 0.00414029679422, -0.0216401454975,
         0.999557249008, 0.0149672133247, 0.025715529948, -0.064676986768,
        -0.0257744366974, 0.00375618835797, 0.999660727178, 0.00981073058949,
         0.0, 0.0, 0.0, 1.0]
rate_hz: 20
resolution: [752, 480]
camera_model: pinhole
intrinsics: [458.654, 457.296, 367.215, 248.375] #fu, fv, cu, cv
distortion_model: radial-tangential
distortion_coefficients: [-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05]
"""


def euroc_sequence(evo: Path, root: Path, stamps_ns: list[int]) -> Path:
    cam = root / "mav0" / "cam0"
    frames(cam / "data", [f"{v}.png" for v in stamps_ns], (752, 480))
    (cam / "data.csv").write_text("#timestamp [ns],filename\n" + "".join(f"{v},{v}.png\n" for v in stamps_ns))
    (cam / "sensor.yaml").write_text(EUROC_SENSOR)
    gt = root / "mav0" / "state_groundtruth_estimate0"
    gt.mkdir(parents=True)
    shutil.copyfile(evo / "V102_groundtruth.csv", gt / "data.csv")
    return root


def test_euroc_reader_on_v1_02s_own_ground_truth(shared_data, tmp_path):
    """V1_02's state ground truth (200 Hz, IMU body frame) at the estimate's frame times: where a frame time is a
    ground-truth sample the camera pose is that body pose times T_BS exactly; between samples it is interpolated."""
    evo = shared_data / "evo_test_data"
    body = read_euroc_csv(evo / "V102_groundtruth.csv")
    est = read_tum(evo / "V102.txt")
    ns = [int(round(t * 1e9)) for t in est.timestamps]
    ns[1] = int(body.timestamps[5000] * 1e9 + 0.5)  # one frame exactly at a ground-truth sample
    ns = sorted(set(ns))
    seq = open_sequence(euroc_sequence(evo, tmp_path / "V1_02_medium", ns))
    gt = seq.groundtruth()
    assert seq.layout == "euroc" and len(gt) == len(ns)
    k = int(np.flatnonzero(np.abs(gt.timestamps - body.timestamps[5000]) < 1e-6)[0])
    r_body = Rotation.from_quat(body.quaternions[5000]).as_matrix()
    assert np.allclose(gt.positions[k], body.positions[5000] + r_body @ EUROC_T_BS[:3, 3], atol=1e-9)
    assert np.allclose(Rotation.from_quat(gt.quaternions[k]).as_matrix(), r_body @ EUROC_T_BS[:3, :3], atol=1e-9)
    # between samples: positions linear, rotations slerped, then T_BS (computed here independently)
    have = np.isfinite(gt.positions).all(axis=1)
    assert have.mean() > 0.95
    for i in np.flatnonzero(have)[::97]:
        j = int(np.searchsorted(body.timestamps, gt.timestamps[i]))
        t0, t1 = body.timestamps[j - 1], body.timestamps[j]
        w = (gt.timestamps[i] - t0) / (t1 - t0)
        r0, r1 = Rotation.from_quat(body.quaternions[j - 1]), Rotation.from_quat(body.quaternions[j])
        r = (r0 * Rotation.from_rotvec(w * (r0.inv() * r1).as_rotvec())).as_matrix()
        p = (1 - w) * body.positions[j - 1] + w * body.positions[j]
        assert np.allclose(gt.positions[i], p + r @ EUROC_T_BS[:3, 3], atol=1e-9)
    # the estimate evaluates against it: within the camera's lever arm (7 cm) of its ATE against the body's path
    cam_ate = metrics.ate(gt, est, "sim3", 1e-3).translation.rmse
    body_ate = metrics.ate(body, est, "sim3", 0.01).translation.rmse
    assert abs(cam_ate - body_ate) < np.linalg.norm(EUROC_T_BS[:3, 3])


def test_kitti_reader_on_sequence_00s_own_poses(shared_data, tmp_path):
    """KITTI 00's poses (one per frame, no timestamps) with its times.txt: the reader's ground truth is the devkit's,
    and ORB-SLAM2's stereo estimate scores KITTI's 0.70 % against it."""
    evo = shared_data / "evo_test_data"
    root = tmp_path / "dataset" / "sequences" / "00"
    times = read_times(evo / "KITTI_00_gt_times.txt")
    frames(root / "image_0", [f"{i:06d}.png" for i in range(len(times))], (1241, 376))
    shutil.copyfile(evo / "KITTI_00_gt_times.txt", root / "times.txt")
    p0 = "7.188560000000e+02 0 6.071928000000e+02 0 0 7.188560000000e+02 1.852157000000e+02 0 0 0 1 0"
    (root / "calib.txt").write_text(f"P0: {p0}\nP1: {p0}\n")
    (tmp_path / "dataset" / "poses").mkdir()
    shutil.copyfile(evo / "KITTI_00_gt.txt", tmp_path / "dataset" / "poses" / "00.txt")
    seq = open_sequence(root)
    gt = seq.groundtruth()
    ref = read_kitti(evo / "KITTI_00_gt.txt", times)
    assert seq.layout == "kitti" and seq.n_frames == len(times) == len(gt)
    assert np.array_equal(gt.positions, ref.positions) and np.array_equal(gt.timestamps, times)
    assert seq.camera.camera.fx == pytest.approx(718.856) and seq.camera.camera.width == 1241
    orb = read_kitti(evo / "KITTI_00_ORB.txt", times)
    assert metrics.kitti(gt, orb, "none").t_pct == pytest.approx(0.70, abs=0.005)


def test_tum_rgbd_reader_associates_within_20_ms_as_tums_tools_do(shared_data, tmp_path):
    """fr1/xyz's motion-capture ground truth at the frame times of RGBD-SLAM's estimate: the nearest pose within
    0.02 s, so ATE against the reader's ground truth equals ATE with TUM's association of the raw files."""
    evo = shared_data / "evo_test_data"
    est = read_tum(evo / "freiburg1_xyz-rgbdslam.txt")
    root = tmp_path / "rgbd_dataset_freiburg1_xyz"
    names = [f"rgb/{t:.6f}.png" for t in est.timestamps]
    frames(root, names, (640, 480))
    (root / "rgb.txt").write_text(
        "# color images\n# timestamp filename\n"
        + "".join(f"{t:.6f} {n}\n" for t, n in zip(est.timestamps, names, strict=True))
    )
    shutil.copyfile(evo / "freiburg1_xyz-groundtruth.txt", root / "groundtruth.txt")
    seq = open_sequence(root)
    assert seq.layout == "tum-rgbd" and seq.camera.camera.pinhole.fx == pytest.approx(517.3)
    gt = seq.groundtruth()
    raw = read_tum(evo / "freiburg1_xyz-groundtruth.txt")
    est_frames = est.with_timestamps(np.array([float(n[4:-4]) for n in names]))
    ours = metrics.ate(gt, est_frames, "se3", 1e-6).translation.rmse
    tums = metrics.ate(raw, est_frames, "se3", 0.02).translation.rmse
    assert ours == pytest.approx(tums, rel=1e-9)


# ---------------------------------------------------------------- bad input, named with its file before any run


def test_bad_input_is_named_with_its_file(layouts, tmp_path):
    euroc = tmp_path / "euroc" / "V1"
    shutil.copytree(layouts["euroc"], euroc)
    (euroc / "mav0/cam0/sensor.yaml").unlink()
    with pytest.raises(DatasetError, match=r"mav0/cam0/sensor.yaml: missing"):
        open_sequence(euroc)

    rgbd = tmp_path / "rgbd_dataset_freiburg1_synth"
    shutil.copytree(layouts["tum-rgbd"], rgbd)
    unknown = rgbd.rename(tmp_path / "rgbd_dataset_kinect_synth")
    with pytest.raises(DatasetError, match=r"rgbd_dataset_kinect_synth: unknown TUM RGB-D camera"):
        open_sequence(unknown)

    kitti = tmp_path / "kitti" / "sequences" / "00"
    shutil.copytree(layouts["kitti"], kitti)
    (tmp_path / "kitti" / "poses").mkdir()
    poses = (layouts["kitti"].parent.parent / "poses" / "00.txt").read_text().splitlines()
    (tmp_path / "kitti" / "poses" / "00.txt").write_text("\n".join(poses[:-5]) + "\n")
    with pytest.raises(DatasetError, match=rf"poses/00.txt: {FRAMES - 5} poses but {FRAMES} frames"):
        open_sequence(kitti)

    euroc2 = tmp_path / "euroc" / "V2"
    shutil.copytree(layouts["euroc"], euroc2)
    csv = euroc2 / "mav0/cam0/data.csv"
    lines = csv.read_text().splitlines()
    lines[3] = lines[3].replace(",", ".5,", 1)
    csv.write_text("\n".join(lines) + "\n")
    with pytest.raises(DatasetError, match=r"data.csv:4: timestamp '\d+\.5' is not a whole number of nanoseconds"):
        open_sequence(euroc2)


def test_a_spec_names_bad_sequences_before_any_run(layouts, tmp_path):
    """`validate` and the campaign's check: a wrong layout and a missing calibration, every problem at once."""
    from slamrun.engine.campaign import check_sequences
    from slamrun.engine.spec_file import load_spec
    from tests.conftest import write_spec

    euroc = tmp_path / "euroc" / "V1"
    shutil.copytree(layouts["euroc"], euroc)
    (euroc / "mav0/cam0/sensor.yaml").unlink()
    datasets = [
        {"name": "e", "path": str(euroc.parent), "sequences": ["V1"], "layout": "euroc"},
        {"name": "k", "path": str(layouts["kitti"].parent), "sequences": ["00"], "layout": "tum-rgbd"},
    ]
    spec = load_spec(write_spec(tmp_path, tmp_path, [{"name": "reference_vo"}], datasets=datasets))
    assert spec.datasets[0].metrics == ["ate", "rpe"]
    with pytest.raises(DatasetError) as exc:
        check_sequences(spec)
    assert "sensor.yaml: missing" in str(exc.value) and "a kitti sequence (by its files)" in str(exc.value)


def test_identity_changes_with_the_data_and_not_with_the_path(layouts, tmp_path):
    moved = tmp_path / "moved" / layouts["euroc"].name
    shutil.copytree(layouts["euroc"], moved)
    assert sequence_identity(moved) == sequence_identity(layouts["euroc"]) != "none"
    (moved / "mav0/cam0/sensor.yaml").write_text(
        (moved / "mav0/cam0/sensor.yaml").read_text().replace("rate_hz: 20", "rate_hz: 20.0")
    )
    assert sequence_identity(moved) != sequence_identity(layouts["euroc"])
    assert sequence_identity(tmp_path / "not-generated-yet") == "none"
