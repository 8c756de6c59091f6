"""Lanes and CPUs that do not fit are said before any run (issue 63): `cpus_per_lane` beyond the CPUs this process
may use is refused (run.json listed 1,000 CPUs of a 2-CPU machine, the method's own-wait allowance became 0), lanes
that share CPUs are warned about, `measurement: exclusive` with more lanes than CPUs is refused, and a contention
threshold under what a run's own scheduling noise reaches is refused."""

from __future__ import annotations

import os

import pytest

from slamrun.engine.scheduler import make_lanes
from slamrun.engine.spec_file import cpu_fit, load_spec
from slamrun.errors import SpecError
from tests.conftest import fake_method, write_spec

CPUS = len(os.sched_getaffinity(0))


def test_cpus_per_lane_beyond_the_machine_is_refused(tmp_path, tiny_dataset):
    spec = write_spec(tmp_path, tiny_dataset, [fake_method()], cpus_per_lane=1000)
    with pytest.raises(SpecError) as exc:
        load_spec(spec)
    assert f"cpus_per_lane 1000: this process may use {CPUS} CPU(s)" in str(exc.value)
    assert all(len(lane.cpus) <= CPUS for lane in make_lanes(2, 1000))  # never multiplied, whatever asks


def test_lanes_that_share_cpus_are_warned_about(tmp_path, tiny_dataset):
    spec = load_spec(write_spec(tmp_path, tiny_dataset, [fake_method()], lanes=CPUS + 1, cpus_per_lane=CPUS))
    warnings = cpu_fit(spec)[1]
    assert any("lanes share CPUs" in w and f"{CPUS + 1} lanes of {CPUS} CPU(s)" in w for w in warnings), warnings
    spec = load_spec(write_spec(tmp_path, tiny_dataset, [fake_method()], lanes=64))
    assert any(f"64 lanes on {CPUS} CPU(s)" in w for w in cpu_fit(spec)[1])


def test_exclusive_with_more_lanes_than_cpus_is_refused(tmp_path, tiny_dataset):
    spec = write_spec(tmp_path, tiny_dataset, [fake_method()], measurement="exclusive", lanes=CPUS + 2)
    with pytest.raises(SpecError) as exc:
        load_spec(spec)
    assert "measurement: exclusive runs one run at a time" in str(exc.value)


def test_a_contention_threshold_under_a_runs_own_noise_is_refused(tmp_path, tiny_dataset):
    with pytest.raises(SpecError) as exc:
        load_spec(write_spec(tmp_path, tiny_dataset, [fake_method()], contention_pct=1e-9))
    assert "contention_pct" in str(exc.value)
    assert load_spec(write_spec(tmp_path, tiny_dataset, [fake_method()], contention_pct=15)).contention_pct == 15
