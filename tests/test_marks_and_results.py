"""Two results each backend and view shares: the lines under a dataset's views saying what its marks mean
(results.marks.notes), and a supervised run's result with its resource samples (backends.base.supervised_result)."""

from __future__ import annotations

from pathlib import Path

import pytest

from slamrun.backends.base import ExecRequest, ExecResult, supervised_result
from slamrun.backends.monitor import ResourceSeries, Sample
from slamrun.datasets.view import Direction, PreparedView, Profile
from slamrun.results.marks import DIVERGED, LOW_COVERAGE, Flags, notes


def test_no_mark_no_note():
    assert notes({}) == [] and notes({"dso": Flags(done=4)}) == []


def test_each_mark_in_use_has_its_line_naming_its_methods_and_thresholds():
    found = {
        "colmap": Flags(done=10, low_coverage=2, coverage_mark={0.8, 0.5}),
        "dso": Flags(done=4),
        "dpvo": Flags(done=6, low_coverage=1, diverged=3, diverged_at={1.0}),
    }
    assert notes(found) == [
        f"{LOW_COVERAGE} low coverage: done runs with poses for fewer than 0.5 / 0.8 of the frames their method was "
        "given (colmap 2 of 10, dpvo 1 of 6): their figures are of what they tracked, not of the sequence.",
        f"{DIVERGED} diverged: done runs whose ATE exceeds 1 of the ground truth's spread (ate_rel; the dataset sets "
        "no max_ate_rel that would make them failures) (dpvo 3 of 6).",
    ]


def test_a_mark_without_recorded_thresholds_names_the_default():
    found = {"svo": Flags(done=2, low_coverage=2, diverged=1)}
    assert [line.split(" of the")[0] for line in notes(found)] == [
        f"{LOW_COVERAGE} low coverage: done runs with poses for fewer than the dataset's coverage_mark",
        f"{DIVERGED} diverged: done runs whose ATE exceeds 0.5",
    ]


def _request(tmp_path: Path) -> ExecRequest:
    view = PreparedView(tmp_path, "s", Direction.forward, Profile.native, 20, 0.0, 1.0, 640, 480, None)
    return ExecRequest(["true"], tmp_path, view, tmp_path / "log.txt", tmp_path / "resources.csv", 60.0)


@pytest.mark.parametrize(
    "stopped, oom, said_oom",
    [((False, False, None), True, True), ((True, False, None), True, False), ((False, True, None), True, False)],
)
def test_a_supervised_runs_result_writes_its_samples_and_says_oom_only_when_nothing_else_stopped_it(
    tmp_path, stopped, oom, said_oom
):
    series = ResourceSeries([Sample(0.0, 50.0, 100.0, 1), Sample(0.5, 150.0, 200.0, 2)])
    req = _request(tmp_path)
    result = supervised_result(req, series, 137, 2.0, stopped, True, oom)
    assert result == ExecResult(
        exit_code=137,
        wall_s=2.0,
        timed_out=stopped[0],
        cancelled=stopped[1],
        oom=said_oom,
        log_truncated=True,
        resources=series.summary(2.0, 20),
        output_exceeded=None,
    )
    assert result.resources["fps"] == 10.0 and result.resources["cpu_peak_pct"] == 150.0
    assert req.resources_path.read_text().splitlines()[0] == "t_s,cpu_pct,ram_mb,n_procs,gpu_mem_mb,gpu_util_pct"


def test_an_output_past_its_limit_is_said_and_a_local_run_is_never_oom(tmp_path):
    result = supervised_result(_request(tmp_path), ResourceSeries(), 0, 1.0, (False, False, "too large"), False)
    assert result.output_exceeded == "too large" and not result.oom and not result.timed_out
    assert len((tmp_path / "resources.csv").read_text().splitlines()) == 1  # the header: no sample
