"""RPE compares like with like: its interval is the sequence's (frames, seconds, metres along the ground truth),
never the step between the poses a method happened to write; evo's own steps stay available as evo-f / evo-m.
On real estimates of evo's test data (TUM RGB-D fr1/xyz and fr2/desk, EuRoC V1_02), thinned as a method that
writes every 3rd or 5th pose would write them."""

from __future__ import annotations

import numpy as np
import pytest

from slamrun.core.metrics import NoPairs, RpeInterval, poses_at, rpe
from slamrun.core.trajectory import Trajectory, read_euroc_csv, read_tum
from slamrun.datasets.make_synthetic import generate
from slamrun.errors import MetricError
from tests.conftest import SHARED_DATA

EVO = SHARED_DATA / "evo_test_data"
TUM = [
    ("freiburg1_xyz-groundtruth.txt", "freiburg1_xyz-rgbdslam.txt"),
    ("fr2_desk_groundtruth.txt", "fr2_desk_ORB.txt"),
]


@pytest.fixture(scope="module")
def evo_data():
    if not EVO.is_dir():
        pytest.skip(reason=f"{EVO} not found: the real files live in shared/data beside the repo")
    return EVO


def thinned(traj: Trajectory, every: int, first: int = 0) -> Trajectory:
    """Every `every`-th pose from `first`, as a method writing fewer poses (colmap's stride) leaves them."""
    k = slice(first, None, every)
    return Trajectory(traj.timestamps[k], traj.positions[k], traj.quaternions[k])


@pytest.mark.parametrize("gt_file, est_file", TUM)
def test_thinned_estimate_has_the_rpe_of_the_full_one_at_the_default_interval(evo_data, gt_file, est_file):
    """TUM RGB-D layout's default (1 s): the full estimate and the one thinned to every 3rd and 5th pose agree to
    3 %; evo's step of one estimate pose gives the thinned estimate a 1.5x larger figure or more (the issue's case)."""
    gt, est = read_tum(evo_data / gt_file), read_tum(evo_data / est_file)
    default = RpeInterval()
    assert (default.delta, default.unit) == (1.0, "s")
    full = rpe(gt, est, default.delta, default.unit, "sim3", 0.02)
    for every in (3, 5):
        part = rpe(gt, thinned(est, every), default.delta, default.unit, "sim3", 0.02)
        assert part.translation.rmse == pytest.approx(full.translation.rmse, rel=0.03), every
        assert part.rotation_deg.rmse == pytest.approx(full.rotation_deg.rmse, rel=0.05), every
        assert part.pairs < full.pairs / (every - 0.5)  # fewer pairs, never a longer interval
        evo_full = rpe(gt, est, 1, "evo-f", "sim3", 0.02).translation.rmse
        evo_part = rpe(gt, thinned(est, every), 1, "evo-f", "sim3", 0.02).translation.rmse
        assert evo_part > 1.35 * evo_full, (every, evo_part, evo_full)


def test_thinned_euroc_estimate_within_the_spread_of_its_own_offsets(evo_data):
    """EuRoC V1_02 (its state ground truth, the 10 Hz real estimate): at 1 s the thinned estimates' figures lie
    within the spread that the choice of the first pose alone gives (a noisy estimate: a few pairs more or less),
    and the full figure inside the same band; evo-f drifts with the step (2.5x at every 5th pose)."""
    gt, est = read_euroc_csv(evo_data / "V102_groundtruth.csv"), read_tum(evo_data / "V102.txt")
    full = rpe(gt, est, 1, "s", "sim3", 0.02).translation.rmse
    parts = [rpe(gt, thinned(est, 3, k), 1, "s", "sim3", 0.02).translation.rmse for k in range(3)]
    low, high = min(parts), max(parts)
    band = max(high - low, 0.1 * full)
    assert low - band <= full <= high + band, (full, parts)
    evo_parts = [rpe(gt, thinned(est, 5, k), 1, "evo-f", "sim3", 0.02).translation.rmse for k in range(5)]
    assert min(evo_parts) > 2 * rpe(gt, est, 1, "evo-f", "sim3", 0.02).translation.rmse


def test_frames_count_the_sequences_frames_exactly(evo_data):
    """`frames` pairs poses whose frames are exactly delta apart: an estimate of every frame at delta 1 is evo's
    consecutive pairs (same figures); an estimate of every 5th frame has no pair 1 frame apart (said as such), and
    at 5 frames exactly the pairs of every 5th frame."""
    gt, est = read_tum(evo_data / "freiburg1_xyz-groundtruth.txt"), read_tum(evo_data / "freiburg1_xyz-rgbdslam.txt")
    paired = np.isfinite(poses_at(gt, est.timestamps, 0.02).positions).all(axis=1)  # poses with a ground truth
    est = Trajectory(est.timestamps[paired], est.positions[paired], est.quaternions[paired])
    frames = est.timestamps  # the estimate is at every frame of its sequence here
    ours = rpe(gt, est, 1, "frames", "sim3", 0.02, frame_times=frames)
    theirs = rpe(gt, est, 1, "evo-f", "sim3", 0.02)
    assert ours.pairs == theirs.pairs == len(est) - 1
    assert ours.translation.rmse == pytest.approx(theirs.translation.rmse, rel=1e-12)
    sparse = thinned(est, 5)
    with pytest.raises(NoPairs, match="no pose pair 1 frames apart"):
        rpe(gt, sparse, 1, "frames", "sim3", 0.02, frame_times=frames)
    five = rpe(gt, sparse, 5, "frames", "sim3", 0.02, frame_times=frames)
    assert five.pairs == len(sparse) - 1
    # a pose missing in the middle breaks the two pairs through it, and no pair spans the gap
    gap = Trajectory(*(np.delete(a, 40, axis=0) for a in (est.timestamps, est.positions, est.quaternions)))
    assert rpe(gt, gap, 1, "frames", "sim3", 0.02, frame_times=frames).pairs == len(est) - 3
    with pytest.raises(MetricError, match="frame times"):
        rpe(gt, est, 1, "frames", "sim3", 0.02)


def test_metres_are_measured_along_the_ground_truth(evo_data):
    """`m`: the interval is the ground truth's path, so scaling the estimate (monocular: scale unknown) or thinning it
    changes nothing of which pairs are taken; evo-m measures the estimate's own path."""
    gt, est = read_tum(evo_data / "freiburg1_xyz-groundtruth.txt"), read_tum(evo_data / "freiburg1_xyz-rgbdslam.txt")
    big = Trajectory(est.timestamps, est.positions * 7.0, est.quaternions)
    a, b = rpe(gt, est, 0.2, "m", "sim3", 0.02), rpe(gt, big, 0.2, "m", "sim3", 0.02)
    assert a.pairs == b.pairs and a.translation.rmse == pytest.approx(b.translation.rmse, rel=1e-9)
    part = rpe(gt, thinned(est, 3), 0.2, "m", "sim3", 0.02)
    assert part.translation.rmse == pytest.approx(a.translation.rmse, rel=0.05)


@pytest.mark.parametrize(
    "delta, unit, said",
    [(0, "s", "positive"), (1.5, "frames", "whole number"), (-1, "m", "positive"), (1, "sec", "expected one of")],
)
def test_a_bad_interval_is_named(delta, unit, said):
    with pytest.raises(MetricError, match=said):
        RpeInterval(delta, unit)


def test_a_campaign_records_its_interval_and_pairs_and_evaluate_reproduces_them(tmp_path):
    """A dataset's `rpe:` reaches every run (results.csv: rpe_interval, rpe_pairs), the layout's default where it is
    not given, and `slamrun evaluate --gt FOLDER` with the same --delta/--delta-unit gives the same figures."""
    import subprocess
    import sys

    import pandas as pd

    from slamrun.engine.campaign import run_campaign
    from slamrun.engine.spec_file import load_spec
    from tests.conftest import write_spec

    data = tmp_path / "data"
    for name, seed in (("seq_a", 3), ("seq_b", 4)):
        generate(data / name, frames=80, seed=seed, size=(320, 240), layout="euroc")  # ground truth at every frame
    datasets = [
        {
            "name": "every2",
            "path": str(data),
            "sequences": ["seq_a"],
            "layout": "euroc",
            "rpe": {"delta": 2, "unit": "frames"},
        },
        {"name": "default", "path": str(data), "sequences": ["seq_b"], "layout": "euroc"},
    ]
    spec = write_spec(tmp_path, data, [{"name": "reference_vo"}], datasets=datasets, directions=["forward"])
    df = pd.read_csv(run_campaign(load_spec(spec), log=lambda *a: None).results_csv).set_index("dataset")
    assert df.loc["every2", "rpe_interval"] == "2 frames" and df.loc["default", "rpe_interval"] == "1 s"
    n = df.loc["every2", "n_poses"]
    assert df.loc["every2", "rpe_pairs"] == n - 2 and df.loc["default", "rpe_pairs"] > 0
    traj = f"{df.loc['every2', 'run_dir']}/trajectory.txt"
    args = [sys.executable, "-m", "slamrun.cli", "evaluate", "--gt", str(data / "seq_a"), "--metric", "rpe"]
    out = subprocess.run(
        [*args, "--delta", "2", "--delta-unit", "frames", "--json", traj], capture_output=True, text=True
    )
    assert out.returncode == 0, out.stderr
    got = __import__("json").loads(out.stdout)
    assert got["rpe_t_rmse"] == pytest.approx(df.loc["every2", "rpe_t_rmse"], rel=1e-9)
    assert got["rpe_pairs"] == df.loc["every2", "rpe_pairs"] and got["rpe_interval"] == "2 frames"


def test_a_bad_rpe_key_in_a_spec_is_named(tiny_dataset, tmp_path):
    from slamrun.engine.spec_file import load_spec
    from slamrun.errors import SpecError
    from tests.conftest import write_spec

    ds = [{"name": "s", "path": str(tiny_dataset), "sequences": ["seq_a"], "rpe": {"delta": 0.5, "unit": "frames"}}]
    spec = write_spec(tmp_path, tiny_dataset, [{"name": "reference_vo"}], datasets=ds)
    with pytest.raises(SpecError, match="whole number of frames"):
        load_spec(spec)
