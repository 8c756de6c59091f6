"""A plug-in layout's Sequence passes the checks a built-in reader's files pass, before any run, named with the
plug-in and its package; its calls are bounded in time; one plug-in that cannot look at a folder never breaks
another's; a writer places only the files it declares."""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from slamrun.core.trajectory import Trajectory
from slamrun.datasets import layouts, plugin_checks
from slamrun.datasets.layouts import _adopt, open_sequence
from slamrun.datasets.make_synthetic import generate
from slamrun.datasets.protocol import Layout
from slamrun.datasets.sequence import Sequence
from slamrun.errors import DatasetError

WHO = "plug-in layout lab (lab-datasets 1.0)"


@pytest.fixture(scope="module")
def real(tmp_path_factory) -> Sequence:
    """A real sequence as a built-in reader gives it (EuRoC layout: ground truth at every frame)."""
    root = generate(tmp_path_factory.mktemp("seq") / "V1_lab", frames=20, seed=1, size=(64, 48), layout="euroc")
    return open_sequence(root)


def plugin(read, recognise=lambda root: True, **kw) -> Layout:
    return _adopt(Layout("lab", "Lab", recognise, "frames.csv", read, "poses.csv", **kw), "lab-datasets 1.0")


def reads(seq: Sequence) -> Layout:
    return plugin(lambda root: seq)


BAD_SEQUENCES = {
    "unsorted": (lambda s: replace(s, timestamps=s.timestamps[[0, 2, 1, *range(3, 20)]]), "frame times must increase"),
    "nan time": (lambda s: replace(s, timestamps=np.where(np.arange(20) == 5, np.nan, s.timestamps)), "frame 5"),
    "fewer times": (lambda s: replace(s, timestamps=s.timestamps[:-1]), "19 timestamps for 20 frames"),
    "2-D times": (lambda s: replace(s, timestamps=s.timestamps.reshape(4, 5)), "must be a 1-D array"),
    "text times": (lambda s: replace(s, timestamps=["a"] * 20), "must be a 1-D array"),
    "too many frames": (
        lambda s: replace(s, frame_names=("0.png",) * 1_000_001, timestamps=np.arange(1_000_001.0)),
        "1,000,001 frames, more than a sequence can have",
    ),
    "no frames": (lambda s: replace(s, frame_names=(), timestamps=np.array([])), "no frames"),
    "beyond 1e10 s": (lambda s: replace(s, timestamps=s.timestamps + 2e10), "beyond 1e+10 s"),
    "bad exposures": (lambda s: replace(s, exposures_ms=np.zeros(20)), "not a positive time"),
    "no camera": (lambda s: replace(s, camera=None), "not a slamrun.core.camera.CameraFile"),
}


@pytest.mark.parametrize("case", sorted(BAD_SEQUENCES))
def test_a_plugins_bad_sequence_is_a_dataset_error_naming_it(real, case, tmp_path):
    """The issue's cases (unsorted times were charged bad_timestamps, a NaN time ran done, fewer times or a 2-D
    array were infra with an index error, 40 million times took 90 s and 2 GB): each one line before any run."""
    spoil, says = BAD_SEQUENCES[case]
    with pytest.raises(DatasetError) as err:
        reads(spoil(real)).read(tmp_path)
    assert str(err.value).startswith(f"{WHO}: the sequence it read from {tmp_path} cannot be run: ")
    assert says in str(err.value)


def test_a_plugins_good_sequence_reads_as_it_gave_it(real, tmp_path):
    seq = reads(real).read(tmp_path)
    assert seq.frame_names == real.frame_names and np.array_equal(seq.timestamps, real.timestamps)
    gt = seq.groundtruth()
    assert np.allclose(gt.positions, real.groundtruth().positions)


def gt_of(real: Sequence, change) -> Sequence:
    truth = real.groundtruth()
    return replace(real, groundtruth_reader=lambda: change(truth))


def nan_rotation(gt: Trajectory) -> Trajectory:
    q = gt.quaternions.copy()
    q[3] = np.nan
    return Trajectory(gt.timestamps, gt.positions, q)


def no_pose(gt: Trajectory) -> Trajectory:
    nan = np.full_like(gt.positions, np.nan)
    return Trajectory(gt.timestamps, nan, np.full_like(gt.quaternions, np.nan))


def raises(gt: Trajectory) -> Trajectory:
    raise KeyError("qw")


BAD_GROUNDTRUTH = {
    "nan rotation": (nan_rotation, "ground-truth pose at frame 3 holds NaN"),
    "no pose at any frame": (no_pose, "its ground truth has no pose at any of the 20 frames"),
    "scaled quaternion": (lambda gt: Trajectory(gt.timestamps, gt.positions, 2 * gt.quaternions), "norm 2; expected 1"),
    "fewer poses": (lambda gt: Trajectory(gt.timestamps[:5], gt.positions[:5], gt.quaternions[:5]), "5 poses for 20"),
    "other times": (lambda gt: Trajectory(gt.timestamps + 100, gt.positions, gt.quaternions), "not at the frames'"),
    "not a trajectory": (lambda gt: gt.positions, "ndarray, not a slamrun.core.trajectory.Trajectory"),
    "reader raises": (raises, "reading the ground truth"),
}


@pytest.mark.parametrize("case", sorted(BAD_GROUNDTRUTH))
def test_a_plugins_bad_ground_truth_is_a_dataset_error_never_the_methods(real, case, tmp_path):
    """NaN rotations and ground truth at no frame were charged `lost`; a raising reader gave raw tracebacks."""
    change, says = BAD_GROUNDTRUTH[case]
    seq = reads(gt_of(real, change)).read(tmp_path)
    with pytest.raises(DatasetError) as err:
        seq.groundtruth()
    assert str(err.value).startswith(WHO) and says in str(err.value), str(err.value)
    if case == "reader raises":
        assert "KeyError: 'qw'" in str(err.value)


def test_a_plugins_missing_poses_are_whole_nan_rows(real, tmp_path):
    """A frame without a pose (every value NaN) is how built-in readers mark one: accepted."""

    def some_missing(gt: Trajectory) -> Trajectory:
        pos, q = gt.positions.copy(), gt.quaternions.copy()
        pos[:4], q[:4] = np.nan, np.nan
        return Trajectory(gt.timestamps, pos, q)

    gt = reads(gt_of(real, some_missing)).read(tmp_path).groundtruth()
    assert np.isnan(gt.positions[:4]).all() and np.isfinite(gt.positions[4:]).all()


def test_a_hung_plugin_call_is_given_up_after_its_limit(real, tmp_path, monkeypatch):
    monkeypatch.setitem(plugin_checks.TIME_LIMITS_S, "recognise", 0.5)
    monkeypatch.setitem(plugin_checks.TIME_LIMITS_S, "read", 0.5)
    slow = plugin(lambda root: time.sleep(30) or real, recognise=lambda root: time.sleep(30))
    for call, what in ((slow.recognise, "recognising a folder"), (slow.read, "reading the sequence")):
        start = time.monotonic()
        with pytest.raises(DatasetError) as err:
            call(tmp_path)
        assert str(err.value).startswith(f"{WHO}: {what} on {tmp_path} took more than 0.5 s and was given up")
        assert time.monotonic() - start < 10


def test_a_plugin_whose_recognise_raises_never_breaks_another_plugins_folders(real, tmp_path, monkeypatch):
    """One plug-in raising in recognise() broke validate/campaign/evaluate of every other plug-in's folders."""
    broken = _adopt(Layout("aaa", "A", lambda root: 1 / 0, "a.csv", lambda root: real, "a"), "broken-lab 0.1")
    good = _adopt(Layout("lab", "Lab", lambda root: True, "frames.csv", lambda root: real, "p"), "lab-datasets 1.0")
    monkeypatch.setattr(layouts, "_plugins", lambda: ({"aaa": broken, "lab": good}, {}))
    folder = tmp_path / "lab1"
    folder.mkdir()
    assert layouts.detect(folder) == "lab"
    assert open_sequence(folder).frame_names == real.frame_names
    with pytest.raises(DatasetError, match="broken-lab 0.1.*recognising a folder.*ZeroDivisionError"):
        open_sequence(folder, layout="aaa")


def test_a_writer_places_only_the_files_it_declares(tmp_path, monkeypatch):
    """A plug-in writer that staged a file it had not declared in synth_outside replaced a user's data/notes.txt."""
    from slamrun.datasets import make_synthetic

    notes = tmp_path / "notes.txt"
    notes.write_text("a user's notes\n")

    def writer(tmp: Path, s) -> list:
        (tmp / "frames.csv").write_text("0.0,0.png\n")
        staged = tmp / "staged-notes.txt"
        staged.write_text("overwritten\n")
        return [(staged, notes)]

    lab = plugin(lambda root: None, synth=writer)
    monkeypatch.setattr(layouts, "_plugins", lambda: ({"lab": lab}, {}))
    with pytest.raises(DatasetError, match=f"its writer put {notes} beside .*does not declare; nothing was written"):
        make_synthetic.generate(tmp_path / "seq", frames=2, layout="lab")
    assert notes.read_text() == "a user's notes\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt"]
