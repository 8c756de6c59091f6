"""ATE, RPE and KITTI's segment errors against their reference tools, on the real files of
shared/data/evo_test_data (estimates of real systems with each dataset's own ground truth): evo's Python API
for ATE and RPE, an independent transcription of the KITTI development kit for the segment errors."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from slamrun.core.metrics import Alignment, associate, ate, coverage, kitti, rpe
from slamrun.core.trajectory import Trajectory, from_matrices, read_euroc_csv, read_kitti, read_times, read_tum
from slamrun.errors import MetricError, TrajectoryFormatError
from tests.conftest import SHARED_DATA

EVO = SHARED_DATA / "evo_test_data"
TUM_PAIRS = [
    ("fr2_desk_groundtruth.txt", "fr2_desk_ORB.txt"),
    ("fr2_desk_groundtruth.txt", "fr2_desk_ORB_kf_mono.txt"),
    ("freiburg1_xyz-groundtruth.txt", "freiburg1_xyz-ORB_kf_mono.txt"),
    ("freiburg1_xyz-groundtruth.txt", "freiburg1_xyz-rgbdslam.txt"),
    ("freiburg1_xyz-groundtruth.txt", "freiburg1_xyz-rgbdslam_drift.txt"),
    ("freiburg1_xyz-groundtruth.txt", "freiburg1_xyz-rgbdslam_drift_short.txt"),
]
KITTI_ESTIMATES = ["KITTI_00_ORB.txt", "KITTI_00_SPTAM.txt"]
ALIGNMENTS = ["sim3", "se3", "first:50"]


@pytest.fixture(scope="module")
def evo():
    pytest.importorskip("evo", reason="evo (a development dependency) is the reference")
    if not EVO.is_dir():
        pytest.skip(reason=f"{EVO} not found: the real files live in shared/data beside the repo")
    from evo.core import metrics, sync
    from evo.core.trajectory import PoseTrajectory3D
    from evo.tools import file_interface

    return metrics, sync, PoseTrajectory3D, file_interface


def pairs():
    """(name, ground truth, estimate) as slamrun reads them, every fixture pair with a ground truth."""
    out = [(f"{e}", read_tum(EVO / g), read_tum(EVO / e)) for g, e in TUM_PAIRS]
    out.append(("V102.txt", read_euroc_csv(EVO / "V102_groundtruth.csv"), read_tum(EVO / "V102.txt")))
    times = read_times(EVO / "KITTI_00_gt_times.txt")
    gt = read_kitti(EVO / "KITTI_00_gt.txt", times)
    out += [(e, gt, read_kitti(EVO / e, times)) for e in KITTI_ESTIMATES]
    return out


def to_evo(evo, traj: Trajectory):
    _, _, PoseTrajectory3D, _ = evo
    return PoseTrajectory3D(traj.positions, traj.quaternions[:, [3, 0, 1, 2]], traj.timestamps)


def evo_files(evo, case: int):
    """evo's own reading of a pair's files (every row as the file holds it); KITTI's poses at their times."""
    _, _, _, file_interface = evo
    name, gt, est = pairs()[case]
    if case < len(TUM_PAIRS):
        return tuple(file_interface.read_tum_trajectory_file(EVO / f) for f in TUM_PAIRS[case])
    if name == "V102.txt":
        ref = file_interface.read_euroc_csv_trajectory(EVO / "V102_groundtruth.csv")
        return ref, file_interface.read_tum_trajectory_file(EVO / name)
    return to_evo(evo, gt), to_evo(evo, est)


def evo_reference(evo, case: int, alignment: str):
    """evo's associated, aligned pair, from the files."""
    _, sync, _, _ = evo
    ref, e = sync.associate_trajectories(*evo_files(evo, case), max_diff=0.02)
    a = Alignment.parse(alignment)
    e = copy.deepcopy(e)
    e.align(ref, correct_scale=a.kind == "sim3", n=a.first_n or -1)
    return ref, e


def assert_stats(ours, theirs, stats=("rmse", "mean", "median", "max", "min", "std")):
    from evo.core.metrics import StatisticsType

    for name in stats:
        assert getattr(ours, name) == pytest.approx(theirs.get_statistic(StatisticsType(name)), rel=1e-6, abs=1e-9), (
            name
        )


@pytest.mark.parametrize("alignment", ALIGNMENTS)
@pytest.mark.parametrize("case", range(len(TUM_PAIRS) + 1 + len(KITTI_ESTIMATES)))
def test_ate_equals_evo_on_every_real_pair(evo, case, alignment):
    metrics = evo[0]
    name, gt, est = pairs()[case]
    ref, e = evo_reference(evo, case, alignment)
    if alignment.startswith("first:") and ref.num_poses < int(alignment.split(":")[1]):
        # evo fits on every pose when fewer than N pair (numpy's slice); slamrun says so instead of a figure
        with pytest.raises(MetricError, match=f"but {ref.num_poses} pair with the ground truth"):
            ate(gt, est, alignment)
        return
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((ref, e))
    ours = ate(gt, est, alignment)
    assert ours.translation.n == ref.num_poses, name
    assert_stats(ours.translation, ape)


@pytest.mark.parametrize("delta, unit", [(1, "evo-f"), (10, "evo-f"), (0.1, "evo-m")])
@pytest.mark.parametrize("case", range(len(TUM_PAIRS) + 1 + len(KITTI_ESTIMATES)))
def test_rpe_equals_evo_on_every_real_pair(evo, case, delta, unit):
    metrics = evo[0]
    name, gt, est = pairs()[case]
    if unit == "evo-m" and name.startswith("KITTI"):
        delta = 50.0  # KITTI's frames are metres apart
    ref, e = evo_reference(evo, case, "sim3")
    evo_unit = metrics.Unit.frames if unit == "evo-f" else metrics.Unit.meters
    ours = rpe(gt, est, delta=delta, unit=unit, alignment="sim3")
    for relation, mine in (
        (metrics.PoseRelation.translation_part, ours.translation),
        (metrics.PoseRelation.rotation_angle_deg, ours.rotation_deg),
    ):
        ref_rpe = metrics.RPE(relation, delta=delta, delta_unit=evo_unit, all_pairs=False)
        ref_rpe.process_data((ref, e))
        assert mine.n == len(ref_rpe.error), name
        assert_stats(mine, ref_rpe, ("rmse", "mean", "median", "max"))


def kitti_devkit(gt: np.ndarray, est: np.ndarray, lengths=(100, 200, 300, 400, 500, 600, 700, 800), step=10):
    """evaluate_odometry.cpp's calcSequenceErrors, transcribed loop by loop: (mean t_err in %, mean r_err in
    deg/m) over every (first frame, length) segment."""
    dist = [0.0]
    for i in range(1, len(gt)):
        dist.append(dist[-1] + float(np.linalg.norm(gt[i][:3, 3] - gt[i - 1][:3, 3])))
    t_errs, r_errs = [], []
    for first in range(0, len(gt), step):
        for length in lengths:
            last = next((i for i in range(first, len(dist)) if dist[i] > dist[first] + length), -1)
            if last == -1:
                continue
            delta_gt = np.linalg.inv(gt[first]) @ gt[last]
            delta_est = np.linalg.inv(est[first]) @ est[last]
            err = np.linalg.inv(delta_est) @ delta_gt
            a, b, c = err[0, 0], err[1, 1], err[2, 2]
            r_errs.append(np.arccos(max(min(0.5 * (a + b + c - 1.0), 1.0), -1.0)) / length)
            t_errs.append(np.linalg.norm(err[:3, 3]) / length)
    return 100 * np.mean(t_errs), np.degrees(np.mean(r_errs)), len(t_errs)


def poses(traj: Trajectory) -> np.ndarray:
    m = np.tile(np.eye(4), (len(traj), 1, 1))
    m[:, :3, :3] = traj.rotations()
    m[:, :3, 3] = traj.positions
    return m


@pytest.mark.parametrize("name", KITTI_ESTIMATES)
def test_kitti_segments_equal_the_devkit_on_kitti_00(evo, name):
    times = read_times(EVO / "KITTI_00_gt_times.txt")
    gt = read_kitti(EVO / "KITTI_00_gt.txt", times)
    est = read_kitti(EVO / name, times)
    ours = kitti(gt, est, alignment="none")  # stereo estimates: metric scale, no alignment, as the devkit
    t_pct, r_deg, n = kitti_devkit(poses(gt), poses(est))
    assert ours.n_segments == n
    assert ours.t_pct == pytest.approx(t_pct, rel=1e-9)
    assert ours.r_deg_per_m == pytest.approx(r_deg, rel=1e-9)
    assert 0.3 < ours.t_pct < 3.0  # stereo systems on KITTI 00: about 1 %


def test_kitti_segments_of_a_known_scale_error():
    """A straight 1 km drive, one frame a metre, estimated 2 % too long. A segment of length L runs from its first
    frame to the first frame MORE than L metres on (the devkit's lastFrameFromSegmentLength): L + 1 m here, so
    its error is 2 % of L + 1 m, divided by L. No rotation error."""
    n = 1001
    t = np.arange(n) * 0.1
    gt_pos = np.column_stack([np.arange(n, dtype=float), np.zeros(n), np.zeros(n)])
    quat = np.tile([0.0, 0.0, 0.0, 1.0], (n, 1))
    gt, est = Trajectory(t, gt_pos, quat), Trajectory(t, gt_pos * 1.02, quat)
    res = kitti(gt, est, alignment="none")
    # starts every 10 frames, each needing frame first + L + 1: 100 m has 90 segments, ..., 800 m has 20
    counts = {length: len(range(0, n - length - 1, 10)) for length in range(100, 900, 100)}
    expected = sum(c * 2.0 * (length + 1) / length for length, c in counts.items()) / sum(counts.values())
    assert res.n_segments == sum(counts.values()) == 440
    assert res.t_pct == pytest.approx(expected, rel=1e-12) and res.r_deg_per_m == pytest.approx(0.0, abs=1e-9)
    for length, (t_pct, _, segments) in res.per_length.items():
        assert segments == counts[length] and t_pct == pytest.approx(2.0 * (length + 1) / length, rel=1e-12)
    assert kitti(gt, est, alignment="sim3").t_pct == pytest.approx(0.0, abs=1e-9)  # the scale error aligned away


def test_monocular_keyframes_need_a_similarity(evo):
    gt = read_tum(EVO / "freiburg1_xyz-groundtruth.txt")
    est = read_tum(EVO / "freiburg1_xyz-ORB_kf_mono.txt")
    sim, se3 = ate(gt, est, "sim3"), ate(gt, est, "se3")
    assert sim.translation.rmse < se3.translation.rmse and sim.scale != pytest.approx(1.0, abs=0.05)
    share = coverage(est, read_tum(EVO / "freiburg1_xyz-rgbdslam.txt").timestamps, tolerance_s=0.02)
    assert 0 < share < 0.5  # keyframes only


def test_association_follows_evo_at_ties_and_tolerance():
    q = np.tile([0.0, 0.0, 0.0, 1.0], (3, 1))
    gt = Trajectory(np.array([0.0, 1.0, 2.0]), np.eye(3), q)
    est = Trajectory(np.array([0.5, 1.015, 2.5]), np.eye(3), q)
    p = associate(gt, est, tolerance_s=0.5)
    np.testing.assert_array_equal(p.gt.timestamps, [0.0, 1.0, 2.0])  # 0.5: a tie goes to the earlier pose
    assert len(associate(gt, est, tolerance_s=0.02).est) == 1


# ------------------------------------------------------------------ bad input


def test_no_shared_timestamp_is_a_clear_error(evo):
    gt = read_tum(EVO / "fr2_desk_groundtruth.txt")
    est = read_tum(EVO / "freiburg1_xyz-rgbdslam.txt")
    with pytest.raises(MetricError, match="share no timestamp within 0.02 s"):
        ate(gt, est)


def test_a_kitti_estimate_with_another_row_count_names_the_file(evo, tmp_path):
    times = read_times(EVO / "KITTI_00_gt_times.txt")
    short = tmp_path / "short.txt"
    short.write_text("".join((EVO / "KITTI_00_ORB.txt").read_text().splitlines(keepends=True)[:100]))
    with pytest.raises(TrajectoryFormatError, match=f"{short}: 100 KITTI poses but {len(times)} timestamps"):
        read_kitti(short, times)


def test_an_euroc_csv_with_a_missing_column_names_the_file_and_line(evo, tmp_path):
    lines = (EVO / "V102_groundtruth.csv").read_text().splitlines()
    lines[5] = ",".join(lines[5].split(",")[:6])
    bad = tmp_path / "data.csv"
    bad.write_text("\n".join(lines) + "\n")
    with pytest.raises(TrajectoryFormatError, match=f"{bad}:6: 6 columns; expected at least 8"):
        read_euroc_csv(bad)
    lines = (EVO / "V102_groundtruth.csv").read_text().splitlines()
    lines[3] = "1403715524917143.5" + lines[3][lines[3].index(",") :]
    bad.write_text("\n".join(lines) + "\n")
    with pytest.raises(TrajectoryFormatError, match=f"{bad}:4: timestamp .* not a whole number of nanoseconds"):
        read_euroc_csv(bad)


def test_euroc_nanoseconds_become_seconds_exactly(evo):
    gt = read_euroc_csv(EVO / "V102_groundtruth.csv")
    first = (EVO / "V102_groundtruth.csv").read_text().splitlines()[1].split(",")
    assert gt.timestamps[0] == pytest.approx(int(first[0]) / 1e9, abs=1e-9)
    q = [float(first[5]), float(first[6]), float(first[7]), float(first[4])]
    np.testing.assert_allclose(gt.quaternions[0], q / np.linalg.norm(q), rtol=1e-12)
    assert len(from_matrices(gt.timestamps[:2], np.tile(np.eye(4)[:3], (2, 1, 1)))) == 2


def test_the_command_line_gives_the_library_figures_on_every_core(evo):
    import json
    import subprocess
    import sys

    times = EVO / "KITTI_00_gt_times.txt"
    args = ["--metric", "kitti", "--align", "none", "--gt", str(EVO / "KITTI_00_gt.txt"), "--gt-format", "kitti"]
    args += ["--est-format", "kitti", "--times", str(times), "--json", "--jobs", "2"]
    files = [str(EVO / e) for e in KITTI_ESTIMATES]
    out = subprocess.run(
        [sys.executable, "-m", "slamrun.cli", "evaluate", *args, *files], capture_output=True, text=True, check=True
    )
    rows = [json.loads(line) for line in out.stdout.splitlines()]
    gt = read_kitti(EVO / "KITTI_00_gt.txt", read_times(times))
    for row, f in zip(rows, files, strict=True):
        assert row["file"] == f and row["status"] == "ok"
        assert row["kitti_t_pct"] == kitti(gt, read_kitti(f, read_times(times)), alignment="none").t_pct
    bad = subprocess.run(
        [sys.executable, "-m", "slamrun.cli", "evaluate", "--metric", "kitti", "--gt", str(EVO / "KITTI_00_gt.txt")]
        + ["--gt-format", "kitti", files[0]],
        capture_output=True,
        text=True,
    )
    assert bad.returncode == 1 and "--times" in bad.stderr and "Traceback" not in bad.stderr


def test_an_alignment_over_more_poses_than_pair_is_refused_not_fitted_on_all():
    """first:N with fewer than N associated poses: the campaign and `slamrun evaluate` alike say so (the fit
    used to take every pose silently, a figure that is not the one asked for)."""
    from slamrun.core.metrics import Alignment

    rng = np.random.default_rng(0)
    pts = rng.normal(size=(60, 3))
    assert Alignment.parse("first:60").fit(pts, pts).scale == pytest.approx(1.0)
    with pytest.raises(MetricError, match=r"first 100 poses, but 60 .* give N <= 60"):
        Alignment.parse("first:100").fit(pts, pts)
