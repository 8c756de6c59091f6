"""Association as evo's sync.associate_trajectories, on TUM RGB-D fr2/desk's real ground truth
(shared/data/evo_test_data/fr2_desk_groundtruth.txt), whose rows 10859 and 10860 hold one timestamp
(1311868229.5760) with two different poses. Estimates derived from it (seeded noise, a Sim(3) frame, subsampled,
jittered times, denser than the ground truth, repeated and backward timestamps) are written to files and evaluated
by slamrun and by evo's own functions (file_interface, sync, trajectory, metrics) from the same files."""

from __future__ import annotations

import copy
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from slamrun.core.metrics import ate, rpe
from slamrun.core.trajectory import read_tum, read_tum_many, write_tum
from tests.conftest import SHARED_DATA

GT = SHARED_DATA / "evo_test_data" / "fr2_desk_groundtruth.txt"
REPEATED = 1311868229.5760  # the time of data rows 10859 and 10860 (0-based 10858, 10859)
TOL = 0.02  # slamrun's default association tolerance, given to evo as max_diff
REL = 1e-9


@pytest.fixture(scope="module")
def evo():
    pytest.importorskip("evo", reason="evo (a development dependency) is the reference")
    if not GT.is_file():
        pytest.skip(reason=f"{GT} not found: the real files live in shared/data beside the repo")
    from evo.core import metrics, sync
    from evo.tools import file_interface

    return metrics, sync, file_interface


def _gt_rows() -> np.ndarray:
    return np.loadtxt(GT, comments="#")


def _noisy(rows: np.ndarray, rng: np.random.Generator, sigma_m: float = 0.01, sigma_rad: float = 0.01) -> np.ndarray:
    out = rows.copy()
    out[:, 1:4] += rng.normal(0, sigma_m, (len(rows), 3))
    turn = Rotation.from_rotvec(rng.normal(0, sigma_rad, (len(rows), 3)))
    out[:, 4:8] = (Rotation.from_quat(rows[:, 4:8]) * turn).as_quat()
    return out


def _sim3(rows: np.ndarray, seed: int, scale: float) -> np.ndarray:
    """The poses in another frame, at another scale (a monocular estimate's)."""
    frame = Rotation.random(random_state=seed)
    out = rows.copy()
    out[:, 1:4] = scale * frame.apply(rows[:, 1:4]) + np.array([0.5, -2.0, 1.0])
    out[:, 4:8] = (frame * Rotation.from_quat(rows[:, 4:8])).as_quat()
    return out


def _denser(rows: np.ndarray) -> np.ndarray:
    """A pose between each two ground-truth rows besides the rows themselves: more rows than the ground truth,
    so that evo pairs each ground-truth row (both rows of the repeated time) with the estimate."""
    mid = rows[:-1].copy()
    mid[:, 0] = rows[:-1, 0] + 0.4 * (rows[1:, 0] - rows[:-1, 0])
    mid[:, 1:4] = 0.5 * (rows[:-1, 1:4] + rows[1:, 1:4])
    out = np.empty((2 * len(rows) - 1, 8))
    out[0::2], out[1::2] = rows, mid
    return out


def _estimates() -> dict[str, np.ndarray]:
    """Estimates derived from the ground truth, each from its own seeded generator: name -> rows in file order."""
    gt = _gt_rows()
    dup = int(np.flatnonzero(gt[:, 0] == REPEATED)[0])
    out = {}
    rng = np.random.default_rng(1)
    out["noise, every row"] = _noisy(gt, rng)
    rng = np.random.default_rng(2)
    out["sim3, every row"] = _sim3(_noisy(gt, rng, 0.02), seed=2, scale=0.37)
    rng = np.random.default_rng(3)
    sub = _noisy(gt[1::3], rng)  # 33 Hz, holding the first row of the repeated time
    sub[:, 0] += rng.uniform(-0.004, 0.004, len(sub))  # times jittered within the tolerance
    out["subsampled, jittered times"] = _sim3(sub, seed=3, scale=2.5)
    rng = np.random.default_rng(4)
    keyframes = gt[dup - 301 : dup + 300 : 7].copy()  # keyframe 43 at the first row of the repeated time
    keyframes[:, 0] += rng.uniform(-0.008, 0.008, len(keyframes))
    keyframes[43, 0] = REPEATED + 0.0008  # nearer to it than to the next row (1311868229.5794)
    out["keyframes around the repeated time"] = _sim3(_noisy(keyframes, rng, 0.005), seed=4, scale=0.8)
    rng = np.random.default_rng(5)
    own = _noisy(gt[::2], rng)
    again = _noisy(own[[100, 5000]], rng, 0.05, 0.05)  # the estimate repeats two of its times, with other poses
    out["the estimate repeats a time"] = np.insert(own, [101, 5001], again, axis=0)
    rng = np.random.default_rng(6)
    out["denser than the ground truth"] = _noisy(_denser(gt), rng)
    rng = np.random.default_rng(7)
    out["backward (a backward run's file)"] = _sim3(_noisy(gt[::3], rng), seed=7, scale=0.6)[::-1]
    rng = np.random.default_rng(8)
    out["denser and backward"] = _noisy(_denser(gt), rng)[::-1]
    rng = np.random.default_rng(9)
    block = _noisy(gt[::2], rng)
    lo = dup // 2 - 40
    block[lo : lo + 80] = block[lo : lo + 80][::-1]  # a block out of order around the repeated time
    out["a block out of order"] = block
    rng = np.random.default_rng(10)
    out["control: far from the repeated time"] = _sim3(_noisy(gt[2000:3800], rng), seed=10, scale=1.3)
    return out


ESTIMATES = _estimates() if GT.is_file() else {}
NAMES = list(ESTIMATES)


def _write(path: Path, rows: np.ndarray) -> Path:
    np.savetxt(path, rows, fmt=["%.6f"] + ["%.9f"] * 7)
    return path


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("fr2_desk_estimates")
    return {name: _write(folder / f"est_{k:02d}.txt", rows) for k, (name, rows) in enumerate(ESTIMATES.items())}


_EVO_PAIRS: dict = {}


def _evo_aligned(evo, est_path: Path, alignment: str, tolerance_s: float = TOL):
    """evo's pair from the two files: read, associated (ground truth first, as evo_ape does), aligned (each
    computed once in this module)."""
    if (est_path, tolerance_s) not in _EVO_PAIRS:
        _, sync, file_interface = evo
        ref = file_interface.read_tum_trajectory_file(str(GT))
        est = file_interface.read_tum_trajectory_file(str(est_path))
        _EVO_PAIRS[est_path, tolerance_s] = sync.associate_trajectories(ref, est, max_diff=tolerance_s)
    ref, est = _EVO_PAIRS[est_path, tolerance_s]
    if (est_path, tolerance_s, alignment) not in _EVO_PAIRS:
        est = copy.deepcopy(est)
        est.align(ref, correct_scale=alignment == "sim3")
        _EVO_PAIRS[est_path, tolerance_s, alignment] = ref, est
    return _EVO_PAIRS[est_path, tolerance_s, alignment]


def _assert_stats(ours, theirs, n: int) -> None:
    from evo.core.metrics import StatisticsType

    assert ours.n == n
    for name in ("rmse", "mean", "median", "std", "min", "max"):
        want = theirs.get_statistic(StatisticsType(name))
        assert getattr(ours, name) == pytest.approx(want, rel=REL, abs=1e-300), name


@pytest.mark.parametrize("alignment", ["sim3", "se3"])
@pytest.mark.parametrize("name", NAMES)
def test_ate_equals_evo_on_estimates_of_fr2_desk(evo, files, name, alignment):
    metrics = evo[0]
    ref, est = _evo_aligned(evo, files[name], alignment)
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((ref, est))
    ours = ate(read_tum(GT), read_tum(files[name]), alignment, tolerance_s=TOL)
    _assert_stats(ours.translation, ape, ref.num_poses)


def _rpe_cases() -> list[tuple[str, float, str]]:
    """Every estimate at 10 frames and at 0.5 m; at 1 frame (the campaign's RPE) those of fewer than 8,000 rows
    (evo's RPE takes a second per 3,000 pairs)."""
    out = []
    for name, rows in ESTIMATES.items():
        out += [(name, 10, "evo-f"), (name, 0.5, "evo-m")] + ([(name, 1, "evo-f")] if len(rows) < 8000 else [])
    return out


@pytest.mark.parametrize("name, delta, unit", _rpe_cases())
def test_rpe_equals_evo_on_estimates_of_fr2_desk(evo, files, name, delta, unit):
    metrics = evo[0]
    ref, est = _evo_aligned(evo, files[name], "sim3")
    ours = rpe(read_tum(GT), read_tum(files[name]), delta, unit, "sim3", tolerance_s=TOL)
    evo_unit = metrics.Unit.frames if unit == "evo-f" else metrics.Unit.meters
    for relation, mine in (
        (metrics.PoseRelation.translation_part, ours.translation),
        (metrics.PoseRelation.rotation_angle_deg, ours.rotation_deg),
    ):
        theirs = metrics.RPE(relation, delta=delta, delta_unit=evo_unit, all_pairs=False)
        theirs.process_data((ref, est))
        _assert_stats(mine, theirs, len(theirs.error))


def test_evaluate_command_gives_evos_figures(evo, files):
    """`slamrun evaluate` (the batched reader, worker processes) on the files with a repeated or backward time."""
    metrics = evo[0]
    names = ["noise, every row", "subsampled, jittered times", "backward (a backward run's file)"]
    args = [sys.executable, "-m", "slamrun.cli", "evaluate", "--gt", str(GT), "--gt-format", "tum", "--json"]
    for metric, extra in (
        ("ate", ["--align", "se3"]),
        ("rpe", ["--align", "sim3", "--delta", "10", "--delta-unit", "evo-f"]),
    ):
        out = subprocess.run(
            [*args, "--metric", metric, *extra, "--jobs", "2", *(str(files[n]) for n in names)],
            capture_output=True,
            text=True,
            check=True,
        )
        rows = [json.loads(line) for line in out.stdout.splitlines()]
        for name, row in zip(names, rows, strict=True):
            ref, est = _evo_aligned(evo, files[name], "se3" if metric == "ate" else "sim3")
            if metric == "ate":
                theirs = metrics.APE(metrics.PoseRelation.translation_part)
                key = "ate_rmse"
            else:
                theirs = metrics.RPE(metrics.PoseRelation.translation_part, delta=10, all_pairs=False)
                key = "rpe_t_rmse"
            theirs.process_data((ref, est))
            assert row["status"] == "ok", row
            assert row[key] == pytest.approx(theirs.get_statistic(metrics.StatisticsType.rmse), rel=REL), name


def test_evos_default_tolerance_too(evo, files):
    """At evo's own default max_diff (0.01 s), on the jittered estimate: the same pairs, the same figure."""
    metrics = evo[0]
    name = "subsampled, jittered times"
    ref, est = _evo_aligned(evo, files[name], "sim3", tolerance_s=0.01)
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((ref, est))
    _assert_stats(ate(read_tum(GT), read_tum(files[name]), "sim3", 0.01).translation, ape, ref.num_poses)


@pytest.mark.parametrize("seed", range(40))
def test_matching_equals_evos_on_repeated_tied_and_unsorted_times(evo, seed):
    """Times on a coarse grid (ties at equal distance and repeated times are common), sorted or not, either side
    with repeats: the same pairs as evo's matching_time_indices, in the same order."""
    from slamrun.core.metrics import matching_time_indices

    sync = evo[1]
    rng = np.random.default_rng(seed)
    short = rng.integers(0, 40, rng.integers(1, 30)) * 0.5
    long = rng.integers(0, 40, rng.integers(1, 60)) * 0.5
    if seed % 2:
        long = np.sort(long)  # evo's binary search on sorted times, repeats included
    for tol in (0.0, 0.25, 0.5, 1.0):
        want = sync.matching_time_indices(short, long, max_diff=tol)
        got = matching_time_indices(short, long, tol)
        assert (list(got[0]), list(got[1])) == (list(want[0]), list(want[1])), (seed, tol)


def test_a_file_with_a_repeated_or_backward_time_keeps_its_rows_as_read(evo, files, tmp_path):
    """The time-ordered poses (one per time) for TUM-Mono and the campaign, beside every row as the file holds it
    (what evo reads); write_tum writes those rows back, read_tum_many reads what read_tum reads."""
    file_interface = evo[2]
    for name in ("noise, every row", "a block out of order", "the estimate repeats a time"):
        traj = read_tum(files[name])
        theirs = file_interface.read_tum_trajectory_file(str(files[name]))
        rows = traj.rows_as_read()
        assert np.array_equal(rows.timestamps, theirs.timestamps) and np.array_equal(
            rows.positions, theirs.positions_xyz
        )
        assert np.all(np.diff(traj.timestamps) > 0) and len(traj) == len(np.unique(theirs.timestamps))
        write_tum(tmp_path / "again.txt", traj)
        back = read_tum(tmp_path / "again.txt")
        assert np.array_equal(back.rows_as_read().timestamps, rows.timestamps)
        assert np.array_equal(back.timestamps, traj.timestamps) and np.array_equal(back.positions, traj.positions)
        (many,) = read_tum_many([files[name]])
        assert np.array_equal(many.rows_as_read().positions, rows.positions)
    assert read_tum(files["control: far from the repeated time"]).as_read is None  # nothing kept twice


def test_tum_rgbd_ground_truth_at_frames_follows_evo(evo, tmp_path):
    """The campaign's TUM RGB-D ground truth (the sequence's poses at its frames): a frame 1 ms after the repeated
    time and one exactly at it get the row evo pairs with them (the second), so ATE on the frames equals evo's on
    the raw files."""
    import cv2

    from slamrun.datasets.layouts import open_sequence

    metrics = evo[0]
    gt = _gt_rows()
    dup = int(np.flatnonzero(gt[:, 0] == REPEATED)[0])
    times = np.round(np.concatenate([gt[dup - 150 : dup - 3 : 3, 0] + 0.0012, [REPEATED, REPEATED + 0.001]]), 6)
    times = np.concatenate([times, np.round(gt[dup + 3 : dup + 150 : 3, 0] - 0.0007, 6)])
    root = tmp_path / "rgbd_dataset_freiburg2_desk"
    (root / "rgb").mkdir(parents=True)
    names = [f"rgb/{t:.6f}.png" for t in times]
    cv2.imwrite(str(root / names[0]), np.zeros((480, 640, 3), np.uint8))
    for n in names[1:]:
        shutil.copyfile(root / names[0], root / n)
    (root / "rgb.txt").write_text("# timestamp filename\n" + "".join(f"{n[4:-4]} {n}\n" for n in names))
    shutil.copyfile(GT, root / "groundtruth.txt")
    rng = np.random.default_rng(11)
    nearest = np.abs(gt[:, 0][None, :] - times[:, None]).argmin(axis=1)
    est_rows = _sim3(_noisy(gt[nearest], rng), seed=11, scale=0.5)
    est_rows[:, 0] = times
    est_path = _write(tmp_path / "est.txt", est_rows)
    at_frames = open_sequence(root).groundtruth()
    ours = ate(at_frames, read_tum(est_path), "sim3", 1e-3)  # the campaign's association: exact frame times
    ref, est = _evo_aligned(evo, est_path, "sim3")
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((ref, est))
    _assert_stats(ours.translation, ape, ref.num_poses)
