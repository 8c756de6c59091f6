"""The verification table's pieces: the scene's extent, rows merged across calls, the pass rule."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from slamrun.datasets.make_synthetic import generate
from slamrun.images.verify import VerifyRow, holds_standin_network, markdown_table, merged, scene_extent


def test_scene_extent_is_the_camera_paths_bounding_box_diagonal(tmp_path):
    seq = generate(tmp_path / "room", frames=60, seed=0, size=(160, 120))
    gt = np.loadtxt(seq / "groundtruth_full.txt")
    expected = np.linalg.norm(gt[:, 1:4].max(axis=0) - gt[:, 1:4].min(axis=0))
    assert scene_extent(seq) == pytest.approx(expected)
    assert 5.5 < scene_extent(seq) < 6.5  # an ellipse of radii 2.3 and 1.9 m at about the same height
    (seq / "groundtruth_full.txt").unlink()  # a real sequence: its groundtruthSync rows with numbers
    sync = np.loadtxt(seq / "groundtruthSync.txt")
    finite = sync[np.isfinite(sync[:, 1:4]).all(axis=1)]
    assert scene_extent(seq) == pytest.approx(np.linalg.norm(finite[:, 1:4].max(0) - finite[:, 1:4].min(0)))


def test_a_method_passes_only_with_every_run_ok_and_the_settled_median_under_its_bound():
    """The rule: every run done and evaluated, and the median settled error (after the first-processed segment)
    under the bound; e_align, start-up transient included, is shown but no longer decides."""
    ok = VerifyRow("dso", built=True, runs=8, runs_ok=8, settled_rel_median=0.001, settled_rel_max=0.03, bound=0.02)
    assert ok.passed
    assert not VerifyRow("dso", True, runs=8, runs_ok=7, settled_rel_median=0.001, bound=0.02).passed
    assert not VerifyRow("dso", True, runs=8, runs_ok=8, settled_rel_median=0.021, bound=0.02).passed
    assert not VerifyRow("x", built=False, note="build failed: ...").passed
    transient = dict(built=True, runs=8, runs_ok=8, e_align_rel_median=0.12, e_align_rel_max=0.14)
    assert VerifyRow("lsd_slam", **transient, settled_rel_median=0.004, settled_rel_max=0.009).passed
    assert not VerifyRow("lsd_slam", **transient).passed  # a row verified before the rule has no settled figure


def test_rows_of_earlier_calls_are_kept(tmp_path):
    path = tmp_path / "verify.json"
    first = [VerifyRow("ldso", True, runs=8, runs_ok=8, e_align_rel_median=0.001, e_align_rel_max=0.002)]
    first[0].settled_rel_median, first[0].settled_rel_max = 0.001, 0.002
    path.write_text(json.dumps([r.__dict__ | {"passed": True} for r in first]))
    row = VerifyRow("dso", True, runs=8, runs_ok=8, e_align_rel_median=0.0006, e_align_rel_max=0.001)
    row.settled_rel_median, row.settled_rel_max = 0.0004, 0.0005
    table = merged(path, [row])
    assert [r.method for r in table] == ["dso", "ldso"]  # registry order
    text = markdown_table(table)
    assert "| dso | yes |" in text and "| ldso | yes |" in text and "0.0006 (0.0010)" in text


def test_an_image_with_a_standin_network_is_judged_on_its_plumbing_only():
    """An untrained stand-in graph says nothing of accuracy: such an image passes when every run ends done and
    evaluated, whatever its e_align, and the table says the bound was not applied."""
    far = dict(built=True, runs=8, runs_ok=8, e_align_rel_median=0.4, e_align_rel_max=0.9)
    assert not VerifyRow("cnn_dso", **far).passed
    assert VerifyRow("cnn_dso", **far, plumbing_only=True).passed
    assert not VerifyRow("cnn_dso", True, runs=8, runs_ok=7, e_align_rel_median=0.4, plumbing_only=True).passed
    assert "| plumbing only (stand-in network) |" in markdown_table([VerifyRow("cnn_dso", **far, plumbing_only=True)])
    labels = {"slamrun.weights": '{"model_city2kitti.pb": "untrained stand-in with ...: plumbing only"}'}
    assert holds_standin_network(labels) and not holds_standin_network({"slamrun.weights": '{"a.pb": "a.pb sha256 0"}'})
    assert not holds_standin_network({})


def test_a_run_that_ended_done_without_metrics_says_why():
    from slamrun.images.verify import _why_not_ok

    assert _why_not_ok({"failure": None, "status": "done", "eval_status": "incomplete"}) == "not evaluated (incomplete)"
    assert _why_not_ok({"failure": "lost", "status": "failed", "eval_status": "incomplete"}) == "lost"


def test_a_run_lost_for_most_of_its_frames_is_not_ok_a_keyframe_writer_is(tmp_path):
    """SVO lost early and relocalised at the loop's end: 23 poses of 300 and an e_align of 3 % of the extent; it was
    counted ok. A run is ok when done, evaluated and no stretch of over a tenth of its frames went without a pose:
    LDSO, which writes its keyframes only (46 % of the frames, a pose every 2-3 frames), is."""
    from slamrun.images.verify import _why_not_ok, pose_gap, run_ok

    seq = tmp_path / "seq"
    seq.mkdir()
    times = np.arange(300) / 30.0
    np.savetxt(seq / "times.txt", np.column_stack([np.arange(300), times, np.ones(300)]), fmt="%d %.6f %.1f")

    def gap(rows: np.ndarray) -> int:
        path = tmp_path / "trajectory.txt"
        np.savetxt(path, np.column_stack([times[rows], np.zeros((len(rows), 6)), np.ones(len(rows))]), fmt="%.6f")
        return pose_gap(path, seq)

    lost = gap(np.r_[0:10, 287:300])  # 23 poses: 10 at the start, 13 at the end
    keyframes = gap(np.flatnonzero(np.arange(300) % 5 < 2))  # 40 % of the frames, evenly
    assert (lost, keyframes, gap(np.arange(300))) == (277, 3, 0)
    row = {"failure": None, "status": "done", "eval_status": "ok", "e_align": 0.05, "frames": 300}
    assert not run_ok(row | {"gap": lost}) and run_ok(row | {"gap": keyframes})
    assert _why_not_ok(row | {"gap": lost}) == "277 of 300 frames in a row without a pose"
    assert not run_ok(row | {"gap": 0, "e_align": None})


def test_segment_errors_are_taken_in_the_order_the_method_processed_them():
    """A backward run meets the end segment first: its first-processed segment is e_end, its last e_start. The
    medians are relative to each sequence's extent, so a start-up transient shows whatever the direction."""
    from slamrun.images.verify import processed_segments

    extents = {"a": 2.0, "b": 4.0}
    runs = [
        {"sequence": "a", "direction": "forward", "e_start": 0.2, "e_end": 0.002},
        {"sequence": "b", "direction": "backward", "e_start": 0.004, "e_end": 0.4},
        {"sequence": "a", "direction": "backward", "e_start": None, "e_end": 0.2},
    ]
    first, last = processed_segments(runs, extents)
    assert first == pytest.approx(0.1) and last == pytest.approx(0.001)
    assert processed_segments([], extents) == (None, None)
    row = VerifyRow("lsd_slam", True, runs=8, runs_ok=8, e_align_rel_median=0.12, e_align_rel_max=0.14)
    row.seg_first_rel, row.seg_last_rel = first, last
    assert "| 0.10000 / 0.00100 |" in markdown_table([row])


def test_the_settled_error_leaves_out_the_segment_the_run_processed_first(tmp_path, tiny_dataset):
    """On the run folders of a real campaign (reference_vo, forward and backward): spoiling the poses of the segment
    a run processed first (forward: the start; backward: the end) leaves its settled error as it was, spoiling
    the other end changes it."""
    import pandas as pd

    from slamrun.core.trajectory import read_tum, write_tum
    from slamrun.datasets.make_synthetic import generate
    from slamrun.engine.campaign import run_campaign
    from slamrun.engine.spec_file import load_spec
    from slamrun.images.verify import settled_error
    from tests.conftest import write_spec

    data = tmp_path / "data"
    generate(data / "room", frames=80, seed=4)
    datasets = [{"name": "s", "path": str(data), "sequences": ["room"]}]
    res = run_campaign(load_spec(write_spec(tmp_path, data, [{"name": "reference_vo"}], datasets=datasets)))
    runs = pd.read_csv(res.results_csv)
    assert (runs.status == "done").all() and len(runs) == 2
    times = np.loadtxt(data / "room" / "times.txt")[:, 1]
    start, end = times[: int(0.2 * 80) - 2], times[-int(0.2 * 80) + 2 :]
    for run in runs.itertuples():
        path = Path(run.run_dir) / "trajectory.txt"
        clean = settled_error(path, data / "room", run.direction)
        assert clean is not None and clean / scene_extent(data / "room") < 0.05
        first, other = (start, end) if run.direction == "forward" else (end, start)
        for spoiled, same in ((first, True), (other, False)):
            traj = read_tum(path)
            hit = np.isin(np.round(traj.timestamps, 6), np.round(spoiled, 6))
            assert hit.any()
            moved = traj.positions.copy()
            moved[hit] = moved[hit] * 1.5 + 1.0
            bad = tmp_path / f"{run.direction}-{same}.txt"
            write_tum(bad, type(traj)(traj.timestamps, moved, traj.quaternions))
            value = settled_error(bad, data / "room", run.direction)
            assert (value == pytest.approx(clean, rel=1e-9)) if same else (value > 2 * clean), (run.direction, same)
