"""The background view preparer's order and concurrency (a stand-in for views.prepare: the scheduling logic
only; real preparation is tested in test_datasets.py and through every campaign test)."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import runner.preparer as preparer_module
from runner.datasets.views import Direction, Profile
from runner.preparer import ViewPreparer


def test_the_first_views_of_idle_lanes_are_prepared_together_then_one_at_a_time(tmp_path, monkeypatch):
    active, peak, done = [0], [], []
    lock = threading.Lock()

    def fake_prepare(seq, direction, profile, cache, frame_format="png"):
        with lock:
            active[0] += 1
            peak.append((seq.name, active[0]))
        time.sleep(0.3)
        with lock:
            active[0] -= 1
            done.append(seq.name)
        return seq.name

    monkeypatch.setattr(preparer_module, "prepare", fake_prepare)
    order = [(str(tmp_path / n), Direction.forward, Profile.native) for n in ("a", "b", "c", "d")]
    views = ViewPreparer(order, tmp_path, head=2).start()
    assert [views.get(k) for k in order] == ["a", "b", "c", "d"]
    views.close()
    seen = dict(peak)
    assert max(seen["a"], seen["b"]) == 2  # the two lanes' first views at the same time
    assert seen["c"] == 1 and seen["d"] == 1  # later ones alone: the lanes need the cores
    assert sorted(done) == ["a", "b", "c", "d"] and len(done) == 4  # each prepared once


def test_a_view_asked_for_while_it_is_being_prepared_is_prepared_once(tmp_path, monkeypatch):
    calls = []

    def slow_prepare(seq, direction, profile, cache, frame_format="png"):
        calls.append(seq.name)
        time.sleep(0.3)
        return seq.name

    monkeypatch.setattr(preparer_module, "prepare", slow_prepare)
    key = (str(tmp_path / "a"), Direction.forward, Profile.native)
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
