"""The background view preparer's order and concurrency (a stand-in for cache.prepare: the scheduling logic
only; real preparation is tested in test_datasets.py and through every campaign test)."""

from __future__ import annotations

import os
import threading
import time
from pathlib import Path

import pytest

import slamrun.engine.preparer as preparer_module
from slamrun.datasets.perturb import BASELINE
from slamrun.datasets.view import Direction, Profile
from slamrun.engine.preparer import ViewPreparer
from slamrun.errors import DatasetError


def test_views_are_prepared_one_at_a_time_the_idle_lanes_first_views_with_every_core(tmp_path, monkeypatch):
    active, peak, calls = [0], [0], []
    lock = threading.Lock()

    def fake_prepare(seq, direction, profile, cache, workers=2, frame_format="png", perturbation=None):
        with lock:
            active[0] += 1
            peak[0] = max(peak[0], active[0])
            calls.append((seq.name, workers))
        time.sleep(0.1)
        with lock:
            active[0] -= 1
        return seq.name

    monkeypatch.setattr(preparer_module, "prepare", fake_prepare)
    order = [(str(tmp_path / n), Direction.forward, Profile.native, BASELINE) for n in ("a", "b", "c", "d")]
    views = ViewPreparer(order, tmp_path, head=2, workers=1).start()
    assert [views.get(k) for k in order] == ["a", "b", "c", "d"]
    views.close()
    cores = len(os.sched_getaffinity(0))
    assert peak[0] == 1  # one at a time: the first lane starts after one preparation, not two
    assert calls == [("a", cores), ("b", cores), ("c", 1), ("d", 1)]  # each once, the lanes' first with every core


def test_a_view_asked_for_while_it_is_being_prepared_is_prepared_once(tmp_path, monkeypatch):
    calls = []

    def slow_prepare(seq, direction, profile, cache, workers=2, frame_format="png", perturbation=None):
        calls.append(seq.name)
        time.sleep(0.3)
        return seq.name

    monkeypatch.setattr(preparer_module, "prepare", slow_prepare)
    key = (str(tmp_path / "a"), Direction.forward, Profile.native, BASELINE)
    views = ViewPreparer([key], tmp_path, head=2).start()
    got = []
    threads = [threading.Thread(target=lambda: got.append(views.get(key))) for _ in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    views.close()
    assert got == ["a", "a", "a"] and calls == ["a"]
    assert Path(key[0]).name == "a"


def test_a_view_whose_background_preparation_failed_is_prepared_again_when_a_run_asks_again(tmp_path, monkeypatch):
    """A preparation that failed on something passing (the cache deleted under it) is not remembered as the
    view's fate: the run is retried as infrastructure, and its retry prepares the view again."""
    calls = []

    def once_failing_prepare(seq, direction, profile, cache, workers=2, frame_format="png", perturbation=None):
        calls.append(seq.name)
        if len(calls) == 1:
            raise FileNotFoundError(2, "No such file or directory", str(cache / "x.tmp"))
        return seq.name

    monkeypatch.setattr(preparer_module, "prepare", once_failing_prepare)
    key = (str(tmp_path / "a"), Direction.forward, Profile.native, BASELINE)
    views = ViewPreparer([key], tmp_path).start()
    with pytest.raises(FileNotFoundError):
        views.get(key)
    assert views.get(key) == "a" and calls == ["a", "a"]
    views.close()


def test_a_sequence_that_cannot_be_prepared_is_not_prepared_again_for_each_run(tmp_path, monkeypatch):
    calls = []

    def bad_data(seq, direction, profile, cache, workers=2, frame_format="png", perturbation=None):
        calls.append(seq.name)
        raise DatasetError(f"{seq}: frame 3 cannot be decoded")

    monkeypatch.setattr(preparer_module, "prepare", bad_data)
    key = (str(tmp_path / "a"), Direction.forward, Profile.native, BASELINE)
    views = ViewPreparer([key], tmp_path).start()
    for _ in range(3):
        with pytest.raises(DatasetError):
            views.get(key)
    assert calls == ["a"]
    views.close()
