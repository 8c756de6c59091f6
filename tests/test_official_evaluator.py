"""slamrun's TUM-Mono metrics equal the benchmark's own MATLAB evaluator (tum-vision/mono_dataset_code, run under
GNU Octave from its pinned archive) on generated ground truths and estimates with noise, drift, scale and gaps."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from bench import official
from slamrun.core.evaluation import tum_mono_file
from slamrun.core.trajectory import Trajectory, read_tum
from tests.conftest import UPSTREAM, require_upstream


def sequences(tmp: Path, n_frames: int = 400, n_estimates: int = 12) -> tuple[Path, list[Path]]:
    """A TUM-Mono groundtruthSync.txt (start and end segments, NaN rows between) and estimates of it: noise, a
    scale drift, a rotation drift, missing poses, a different Sim(3) frame each."""
    rng = np.random.default_rng(7)
    t = 100.0 + np.arange(n_frames) / 30.0
    phase = np.linspace(0, 2 * np.pi, n_frames)
    pos = np.column_stack([3 * np.cos(phase), 2 * np.sin(phase), 0.3 * np.sin(3 * phase)])
    quat = Rotation.from_euler("z", phase[:, None]).as_quat()
    gt = np.column_stack([t, pos, quat])
    seg = n_frames // 5
    gt[seg:-seg, 1:] = np.nan
    gt_path = tmp / "groundtruthSync.txt"
    np.savetxt(gt_path, gt, fmt="%.9f")
    files = []
    for k in range(n_estimates):
        drift = 1 + 0.002 * k * np.arange(n_frames) / n_frames
        est = pos * drift[:, None] + rng.normal(0, 0.01 * (k + 1), pos.shape)
        turn = Rotation.from_euler("z", (0.003 * k * np.arange(n_frames))[:, None]).as_matrix()
        est = np.einsum("nij,nj->ni", turn, est)  # a rotation drift
        frame = Rotation.random(random_state=k).as_matrix()
        est = (0.5 + 0.3 * k) * est @ frame.T + rng.normal(0, 5, 3)
        keep = rng.random(n_frames) > 0.1 * (k % 3)
        path = tmp / f"est_{k:02d}.txt"  # no header line: the official importdata reads bare rows only
        np.savetxt(path, np.column_stack([t[keep], est[keep], quat[keep]]), fmt="%.17g")
        files.append(path)
    return gt_path, files


@pytest.mark.skipif(official.octave() is None, reason="GNU Octave not installed (apt-get install octave; .ci/run does)")
def test_slamrun_equals_the_official_tum_mono_evaluator(tmp_path):
    require_upstream(UPSTREAM / official.SOURCES["mono_dataset_code"].filename)
    gt_path, files = sequences(tmp_path)
    ref = official.evaluate(gt_path, files, tmp_path, UPSTREAM)
    data = np.loadtxt(gt_path)
    gt = Trajectory(data[:, 0], data[:, 1:4], data[:, 4:8])
    for f in files:
        ours = tum_mono_file(gt, read_tum(f))
        theirs = ref[str(f.resolve())]
        assert ours.n_poses == theirs["n_poses"]
        for name in ("e_t", "e_r", "e_s", "e_align", "e_start", "e_end", "e_rmse"):
            assert getattr(ours, name) == pytest.approx(theirs[name], rel=1e-6, abs=1e-9), (f.name, name)


@pytest.mark.skipif(official.octave() is None, reason="GNU Octave not installed (apt-get install octave; .ci/run does)")
def test_a_repeated_timestamp_counts_every_row_as_the_official_evaluator_does(tmp_path):
    """An estimate that repeats two of its times with other poses (and one written backward): the official code
    sorts the rows and keeps every one, so slamrun's figures and pose count take every row too."""
    from slamrun.core.evaluation import tum_mono_many

    require_upstream(UPSTREAM / official.SOURCES["mono_dataset_code"].filename)
    gt_path, files = sequences(tmp_path, n_estimates=2)
    rows = np.loadtxt(files[0])
    again = rows[[10, 300]].copy()
    again[:, 1:4] += 0.3
    repeated = tmp_path / "repeated.txt"
    np.savetxt(repeated, np.insert(rows, [11, 301], again, axis=0), fmt="%.17g")
    backward = tmp_path / "repeated_backward.txt"
    np.savetxt(backward, np.insert(rows, [11, 301], again, axis=0)[::-1], fmt="%.17g")
    ref = official.evaluate(gt_path, [repeated, backward], tmp_path, UPSTREAM)
    data = np.loadtxt(gt_path)
    gt = Trajectory(data[:, 0], data[:, 1:4], data[:, 4:8])
    for f in (repeated, backward):
        theirs = ref[str(f.resolve())]
        for ours in (tum_mono_file(gt, read_tum(f)), tum_mono_many(gt, [read_tum(f)])[0]):
            assert ours.n_poses == theirs["n_poses"] == len(rows) + 2
            for name in ("e_t", "e_r", "e_s", "e_align", "e_start", "e_end", "e_rmse"):
                assert getattr(ours, name) == pytest.approx(theirs[name], rel=1e-6, abs=1e-9), (f.name, name)
