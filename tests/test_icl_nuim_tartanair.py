"""ICL-NUIM (its TUM RGB-D-compatible release) and TartanAir (v1): recognised, read, written by `slamrun synth`,
downloaded (ICL-NUIM, from a server on 127.0.0.1), and run end to end; their conventions checked against golden
values worked out from the datasets' own definitions (ICL-NUIM's published camera with fy -480, TartanAir's NED axes),
and through reference_vo: a method's estimate agrees with the ground truth as slamrun carries it, and not with the
poses as the datasets publish them."""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys
import tarfile
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation

from slamrun.core import metrics
from slamrun.core.trajectory import Trajectory, read_tum
from slamrun.datasets import icl_nuim, tartanair
from slamrun.datasets.layouts import detect, open_sequence
from slamrun.datasets.synth import Synth
from slamrun.errors import DatasetError

ROOT = Path(__file__).resolve().parents[1]
FRAMES = 60
SEED = 4  # a loop reference_vo and colmap (every 5th frame) track in 60 frames, in both layouts
NAMES = {"icl-nuim": "living_room_traj0_frei_png", "tartanair": "P000"}
LOOP_M = 2 * np.pi * 2.1  # about the synthetic loop's length


def slamrun(*args, env: dict | None = None, timeout: float = 600) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "slamrun.cli", *map(str, args)],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=ROOT,
        env={**os.environ, **(env or {})},
    )


@pytest.fixture(scope="module")
def sequences(tmp_path_factory) -> dict[str, Path]:
    """One synthetic sequence of each layout, written by `slamrun synth --layout ...`."""
    root = tmp_path_factory.mktemp("layouts")
    out = {}
    for layout, name in NAMES.items():
        folder = root / layout / name
        done = slamrun("synth", folder, "--layout", layout, "--frames", FRAMES, "--seed", SEED)
        assert done.returncode == 0, done.stderr
        assert f"{FRAMES} frames, {layout} layout" in done.stdout
        out[layout] = folder
    return out


def true_poses(n: int = FRAMES) -> np.ndarray:
    """The synthetic camera-to-world poses (x right, y down, z forward) at the frames."""
    s = Synth(n, SEED, (640, 480), "indoor", "x")
    return s.poses_at(s.scene, np.arange(n) / (n - 1))


def rotation_deg(quats: np.ndarray, rots: np.ndarray) -> np.ndarray:
    return np.degrees((Rotation.from_quat(quats).inv() * Rotation.from_matrix(rots)).magnitude())


def frame_files(folder: Path, names: list[str]) -> None:
    """640x480 colour PNGs under `names` (one file, hard-linked)."""
    first = folder / names[0]
    first.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(first), np.full((480, 640, 3), 120, np.uint8))
    for name in names[1:]:
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        os.link(first, folder / name)


# ---------------------------------------------------------------------------------------------------- recognition


def test_each_folder_is_recognised_as_its_layout(sequences, tmp_path):
    assert detect(sequences["icl-nuim"]) == "icl-nuim" and detect(sequences["tartanair"]) == "tartanair"
    # ICL-NUIM given a TUM-style rgb.txt (as some conversion scripts add) is still ICL-NUIM: its *.gt.freiburg says so
    copy = tmp_path / "traj1_frei_png"
    (copy / "rgb").mkdir(parents=True)
    for name in ("associations.txt", "livingRoom0.gt.freiburg"):
        (copy / name).write_bytes((sequences["icl-nuim"] / name).read_bytes())
    (copy / "rgb.txt").write_text("0 rgb/0.png\n")
    assert detect(copy) == "icl-nuim"
    lone = tmp_path / "P001"
    (lone / "image_left").mkdir(parents=True)
    assert detect(lone) == "tartanair"
    with pytest.raises(DatasetError, match="a tartanair sequence \\(by its files\\), but its dataset says layout: "):
        open_sequence(sequences["tartanair"], "icl-nuim")


# ---------------------------------------------------------------------------------------------------- ICL-NUIM


def test_icl_nuim_reader_gives_frames_at_30_hz_the_published_camera_and_the_poses_of_a_y_down_camera(sequences):
    seq = open_sequence(sequences["icl-nuim"])
    assert seq.layout == "icl-nuim" and seq.n_frames == FRAMES and seq.frame_names[:2] == ("rgb/0.png", "rgb/1.png")
    assert np.allclose(seq.timestamps, np.arange(FRAMES) / 30.0)
    cam = seq.camera.camera
    assert (cam.width, cam.height, cam.fx, cam.fy, cam.cx, cam.cy) == (640, 480, 481.20, 480.00, 319.50, 239.50)
    gt = seq.groundtruth()
    truth = true_poses()
    assert np.isnan(gt.positions[0]).all()  # the release has no pose for frame 0
    assert np.abs(gt.positions[1:] - truth[1:, :3, 3]).max() < 1e-6
    assert rotation_deg(gt.quaternions[1:], truth[1:, :3, :3]).max() < 1e-5
    # the file as the release has it: frame numbers, and the y-up camera's poses in the mirrored world
    released = read_tum(sequences["icl-nuim"] / "livingRoom0.gt.freiburg")
    assert np.array_equal(released.timestamps, np.arange(1, FRAMES))
    assert np.allclose(released.positions, truth[1:, :3, 3] * [1, -1, 1], atol=1e-6)


def test_the_published_camera_with_fy_minus_480_sees_a_point_where_slamruns_camera_sees_it(tmp_path):
    """Golden values from the release's definition: a point P of its world, seen from its pose T with fx 481.20,
    fy -480.00, cx 319.50, cy 239.50, lands on pixel (u, v); slamrun's camera (fy +480) at the reader's pose of
    that frame must see the same scene point (the mirrored world's S P) on the same pixel."""
    root = tmp_path / "traj3_frei_png"
    frame_files(root, ["rgb/0.png", "rgb/1.png"])
    (root / "associations.txt").write_text("0 depth/0.png 0 rgb/0.png\n1 depth/1.png 1 rgb/1.png\n")
    rot = Rotation.from_euler("xyz", [12.0, -35.0, 7.0], degrees=True)
    t = np.array([0.4, 1.3, -2.25])
    qx, qy, qz, qw = rot.as_quat()
    (root / "traj3.gt.freiburg").write_text(f"1 {t[0]} {t[1]} {t[2]} {qx} {qy} {qz} {qw}\n")
    seq = open_sequence(root)
    gt = seq.groundtruth()
    assert np.isnan(gt.positions[0]).all() and gt.timestamps[1] == pytest.approx(1 / 30)
    for p in ([0.3, 0.8, 1.5], [-1.0, -0.5, 2.0], [2.0, 1.0, 0.5]):
        p = np.array(p)
        x, y, z = rot.inv().apply(p - t)  # the release's camera coordinates
        if z <= 0:
            continue
        u, v = 481.20 * x / z + 319.50, -480.00 * y / z + 239.50
        cam = seq.camera.camera
        r_s = Rotation.from_quat(gt.quaternions[1])
        xs, ys, zs = r_s.inv().apply(p * [1, -1, 1] - gt.positions[1])
        assert (cam.fx * xs / zs + cam.cx, cam.fy * ys / zs + cam.cy) == pytest.approx((u, v), abs=1e-9)


def test_icl_nuim_problems_are_named_with_their_file_and_line(sequences, tmp_path):
    import shutil

    bad = tmp_path / "living_room_traj1_frei_png"
    shutil.copytree(sequences["icl-nuim"], bad)
    listing = bad / "associations.txt"
    lines = listing.read_text().splitlines()
    lines[1] = "1 depth/1.png rgb/1.png"
    listing.write_text("\n".join(lines) + "\n")
    with pytest.raises(DatasetError, match="associations.txt:2: .*expected 'k depth/k.png k rgb/k.png'"):
        open_sequence(bad)
    lines[1] = "1 depth/1.png 1 rgb/1.png"
    listing.write_text("\n".join(lines) + "\n")
    (bad / "rgb" / "7.png").unlink()
    (bad / "traj1.gt.freiburg").write_text("1 0 0 0 0 0 0 1\n")
    with pytest.raises(DatasetError) as exc:
        open_sequence(bad)
    assert "2 *.gt.freiburg files" in str(exc.value)
    (bad / "traj1.gt.freiburg").unlink()
    with pytest.raises(DatasetError, match="1 frame\\(s\\) listed in associations.txt missing \\(e.g. rgb/7.png\\)"):
        open_sequence(bad)


# ---------------------------------------------------------------------------------------------------- TartanAir


def test_tartanair_reader_gives_frames_at_20_hz_the_published_camera_and_the_ned_poses_in_camera_axes(sequences):
    seq = open_sequence(sequences["tartanair"])
    assert seq.layout == "tartanair" and seq.n_frames == FRAMES and seq.frame_names[0] == "000000_left.png"
    assert np.allclose(seq.timestamps, np.arange(FRAMES) / 20.0)
    cam = seq.camera.camera
    assert (cam.width, cam.height, cam.fx, cam.fy, cam.cx, cam.cy) == (640, 480, 320.0, 320.0, 320.0, 240.0)
    gt = seq.groundtruth()
    truth = true_poses()
    assert np.abs(gt.positions - truth[:, :3, 3]).max() < 1e-6
    assert rotation_deg(gt.quaternions, truth[:, :3, :3]).max() < 1e-5
    rows = np.loadtxt(sequences["tartanair"] / "pose_left.txt")
    assert rows.shape == (FRAMES, 7) and not np.allclose(rows[:, :3], truth[:, :3, 3], atol=0.1)  # NED as published


def test_tartanair_ned_axes_carried_to_the_camera_golden(tmp_path):
    """Golden values from the NED definition: at N 1, E 2, D 3 with no rotation the camera looks north; slamrun's
    camera (x right, y down, z forward) is then at x = east 2, y = down 3, z = north 1 with no rotation. Turned 90
    degrees to the right (yaw about down), it looks east (the world's x), its right is south (-z), its down is down."""
    root = tmp_path / "P002"
    frame_files(root / "image_left", ["000000_left.png", "000001_left.png"])
    s = np.sqrt(0.5)
    (root / "pose_left.txt").write_text(f"1 2 3 0 0 0 1\n0 0 0 0 0 {s} {s}\n")
    gt = open_sequence(root).groundtruth()
    assert gt.positions[0] == pytest.approx([2, 3, 1]) and gt.positions[1] == pytest.approx([0, 0, 0])
    assert Rotation.from_quat(gt.quaternions[0]).magnitude() == pytest.approx(0, abs=1e-12)
    axes = Rotation.from_quat(gt.quaternions[1]).as_matrix()  # columns: the camera's x, y, z in the world
    assert axes[:, 2] == pytest.approx([1, 0, 0]) and axes[:, 0] == pytest.approx([0, 0, -1])
    assert axes[:, 1] == pytest.approx([0, 1, 0])


def test_tartanair_problems_are_named_with_their_file_and_line(sequences, tmp_path):
    import shutil

    bad = tmp_path / "P003"
    shutil.copytree(sequences["tartanair"], bad)
    poses = bad / "pose_left.txt"
    lines = poses.read_text().splitlines()
    poses.write_text("\n".join(lines[:1] + [" ".join(lines[1].split()[:6])] + lines[2:]) + "\n")
    with pytest.raises(DatasetError, match="pose_left.txt:2: 6 values; expected 7 finite numbers"):
        open_sequence(bad).groundtruth()
    poses.write_text("\n".join(lines[:-1]) + "\n")
    with pytest.raises(DatasetError, match=f"pose_left.txt: {FRAMES - 1} poses but {FRAMES} frames"):
        open_sequence(bad)
    poses.write_text("\n".join(lines) + "\n")
    (bad / "image_left" / "000004_left.png").unlink()
    with pytest.raises(DatasetError, match="frame 000004_left.png missing"):
        open_sequence(bad)


def test_a_fifo_as_a_listing_a_ground_truth_or_a_frame_never_blocks(sequences, tmp_path):
    """A FIFO nobody writes (a plain open() blocks for ever) in each file a reader opens: `slamrun validate` ends
    at once naming it, as for every other layout (tests/test_bad_data.py)."""
    import shutil

    from tests.test_bad_data import refused

    cases = [
        ("icl-nuim", "associations.txt", "not a regular file"),
        ("icl-nuim", "livingRoom0.gt.freiburg", "not a regular file"),
        ("icl-nuim", "rgb/5.png", "FIFO"),
        ("tartanair", "pose_left.txt", "not a regular file"),
        ("tartanair", "image_left/000003_left.png", "FIFO"),
    ]
    for i, (layout, name, why) in enumerate(cases):
        folder = tmp_path / f"data{i}" / NAMES[layout]
        shutil.copytree(sequences[layout], folder, copy_function=os.link)
        (folder / name).unlink()
        os.mkfifo(folder / name)
        (tmp_path / f"spec{i}").mkdir()
        refused(folder, layout, tmp_path / f"spec{i}", name, why)


# ---------------------------------------------------------------------------------------------------- end to end


HALF_S = {"delta": 0.5, "unit": "s"}


@pytest.fixture(scope="module")
def campaign(sequences, tmp_path_factory) -> tuple[Path, pd.DataFrame]:
    """reference_vo and colmap, forward and backward, on both sequences."""
    from slamrun.engine.campaign import run_campaign
    from slamrun.engine.spec_file import load_spec
    from tests.conftest import write_spec

    root = tmp_path_factory.mktemp("campaign")
    datasets = [  # RPE over half a second: colmap's every 5th frame at 10 and 30 Hz, on these short sequences
        {"name": layout, "path": str(folder.parent), "sequences": [folder.name], "layout": layout, "rpe": HALF_S}
        for layout, folder in sequences.items()
    ]
    methods = [
        {"name": "reference_vo"},
        {"name": "colmap", "params": {"stride": 5, "max_features": 600, "overlap": 4, "max_image_size": 480}},
    ]
    spec = write_spec(root, root, methods, datasets=datasets, trials=1, timeout_s=300)
    res = run_campaign(load_spec(spec), on_event=None)
    return root, pd.read_csv(res.results_csv)


def test_both_layouts_end_to_end_with_ate_and_rpe(campaign):
    _, df = campaign
    assert len(df) == 2 * 2 * 2
    assert df.status.eq("done").all(), df[["method", "dataset", "direction", "status", "message"]]
    assert df.eval_status.eq("ok").all() and df.ate_rmse.notna().all() and df.rpe_t_rmse.notna().all()
    vo = df[df.method == "reference_vo"]
    assert (vo.ate_rmse < 0.01 * LOOP_M).all() and (vo.rpe_r_rmse < 5.0).all(), vo  # over half a second


def estimates(df: pd.DataFrame, layout: str) -> list[Trajectory]:
    """The runs' estimates with poses enough to fix an alignment (15): reference_vo's both directions, at least
    (colmap, every 5th frame, registers a few)."""
    runs = df[(df.dataset == layout) & (df.n_poses >= 15)]
    assert set(runs[runs.method == "reference_vo"].direction) == {"forward", "backward"}, runs
    return [read_tum(Path(d) / "trajectory.txt") for d in runs.run_dir]


def orientation_errors_deg(gt: Trajectory, est: Trajectory) -> np.ndarray:
    """Each estimated camera's orientation against the ground truth's, after the sim3 alignment of positions."""
    pairs = metrics.associate(gt, est)
    sim = metrics.Alignment.parse("sim3").fit(pairs.est.positions, pairs.gt.positions)
    est_rot = metrics.aligned(pairs.est, sim)[:, :3, :3]
    return rotation_deg(pairs.gt.quaternions, est_rot)


def without_nan(traj: Trajectory) -> Trajectory:
    ok = np.isfinite(traj.positions).all(axis=1)
    return Trajectory(traj.timestamps[ok], traj.positions[ok], traj.quaternions[ok])


def test_icl_nuim_estimates_agree_with_the_mirrored_poses_and_not_with_the_released_ones(campaign, sequences):
    """Methods see the images with fy +480: their cameras point where the reader's poses point (a few degrees),
    while the release's own poses, as they are (the flip ignored), are 20 degrees or more away after any alignment."""
    _, df = campaign
    gt = without_nan(open_sequence(sequences["icl-nuim"]).groundtruth())
    for est in estimates(df, "icl-nuim"):
        assert np.median(orientation_errors_deg(gt, est)) < 10
        assert np.median(orientation_errors_deg(icl_nuim.mirror_y(gt), est)) > 20


def test_tartanair_estimates_agree_with_the_carried_poses_and_not_with_the_ned_ones(campaign, sequences):
    _, df = campaign
    gt = open_sequence(sequences["tartanair"]).groundtruth()
    m = tartanair.NED_TO_CAMERA
    ned = Trajectory(gt.timestamps, gt.positions @ m, Rotation.from_matrix(m.T @ gt.rotations() @ m).as_quat())
    for est in estimates(df, "tartanair"):
        assert np.median(orientation_errors_deg(gt, est)) < 10
        assert np.median(orientation_errors_deg(ned, est)) > 20


def test_evaluate_from_the_folder_equals_the_campaign_and_a_raw_file_says_what_it_is(campaign, sequences):
    _, df = campaign
    for layout, folder in sequences.items():
        row = df[(df.method == "reference_vo") & (df.dataset == layout) & (df.direction == "forward")].iloc[0]
        est = Path(row.run_dir) / "trajectory.txt"
        out = slamrun("evaluate", "--gt", folder, "--json", "--delta", "0.5", "--delta-unit", "s", est)
        assert out.returncode == 0 and "Traceback" not in out.stderr, out.stderr
        (got,) = [json.loads(line) for line in out.stdout.splitlines()]
        for name in ("ate_rmse", "rpe_t_rmse", "rpe_r_rmse", "rpe_pairs"):
            assert got[name] == pytest.approx(row[name], rel=1e-9, abs=1e-12), (layout, name)
    released = sequences["icl-nuim"] / "livingRoom0.gt.freiburg"
    est = Path(df[df.dataset == "icl-nuim"].run_dir.iloc[0]) / "trajectory.txt"
    raw = slamrun("evaluate", "--gt", released, "--metric", "ate", est)
    assert "y-up camera (fy -480)" in raw.stderr and f"--gt {sequences['icl-nuim']}" in raw.stderr
    raw = slamrun("evaluate", "--gt", sequences["tartanair"] / "pose_left.txt", est)  # no times: not a TUM file
    assert raw.returncode == 1 and "Traceback" not in raw.stderr and len(raw.stderr.splitlines()) == 1
    assert "no times and are in NED axes" in raw.stderr and f"--gt {sequences['tartanair']}" in raw.stderr


# ---------------------------------------------------------------------------------------------------- download


def tgz(folder: Path, top: str | None) -> bytes:
    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w:gz") as tar:
        for f in sorted(p for p in folder.rglob("*") if p.is_file()):
            tar.add(f, (f"{top}/" if top else "") + str(f.relative_to(folder)))
    return buf.getvalue()


def test_icl_nuim_downloads_by_the_sites_archive_names(sequences, tmp_path):
    """living_room_trajK_frei_png.tar.gz and (the office) trajK_frei_png.tar.gz, members at the archive's top as the
    site packs them, under a mirror given with --url; names as papers give them (lr_kt0, of_kt2) or the folders'."""
    from slamrun.cli import main
    from tests.conftest import loopback_server

    data = tgz(sequences["icl-nuim"], None)
    routes = {"/icl/living_room_traj0_frei_png.tar.gz": data, "/icl/traj2_frei_png.tar.gz": data}
    with loopback_server(routes) as (base, hits):
        args = ["dataset", "download", "icl-nuim", str(tmp_path), "--sequences", "lr_kt0,of_kt2", "--url"]
        assert main([*args, f"{base}/icl"]) == 0
        assert hits == ["/icl/living_room_traj0_frei_png.tar.gz", "/icl/traj2_frei_png.tar.gz"]
        assert sorted(p.name for p in tmp_path.iterdir()) == ["living_room_traj0_frei_png", "traj2_frei_png"]
        for folder in tmp_path.iterdir():
            assert open_sequence(folder).layout == "icl-nuim"
        assert main([*args[:-2], "living_room_traj0_frei_png", "--url", f"{base}/icl"]) == 0 and len(hits) == 2
        out = slamrun("dataset", "download", "icl-nuim", tmp_path, "--sequences", "lr_kt7", "--url", f"{base}/icl")
        assert out.returncode == 1 and "lr_kt7: not icl-nuim sequences" in out.stderr
    out = slamrun("dataset", "download", "tartanair", tmp_path)
    assert out.returncode == 1 and "tartanair_tools" in out.stderr and "Traceback" not in out.stderr


def test_icl_nuim_downloads_the_studys_eight_by_default():
    from slamrun.datasets.download import remote_archives

    names = icl_nuim.LAYOUT.download.names(None)
    expected = [f"living_room_traj{k}_frei_png" for k in range(4)] + [f"traj{k}_frei_png" for k in range(4)]
    assert remote_archives("icl-nuim", names, "http://m/") == [(n, f"http://m/{n}.tar.gz") for n in expected]


def test_synth_names_an_unknown_layout(tmp_path):
    out = slamrun("synth", tmp_path / "x", "--layout", "icl_nuim", "--frames", 30)
    assert out.returncode == 1 and "unknown layout 'icl_nuim'" in out.stderr and "icl-nuim" in out.stderr


@pytest.mark.parametrize("name", ["icl-tartanair-demo.yaml", "icl-nuim.yaml"])
def test_the_example_specs_load(name):
    import slamrun.methods
    from slamrun.engine.spec_file import load_spec

    spec = load_spec(ROOT / "configs" / name, check_files=False)
    assert [d.layout for d in spec.datasets] == ["icl-nuim", "tartanair"]
    assert all(d.metrics == ["ate", "rpe"] for d in spec.datasets)
    for m in spec.methods:
        slamrun.methods.get(m.name)(m.params)  # their parameters are the methods' own
