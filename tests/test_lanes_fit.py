"""Lanes sized by the method: each method declares the threads it keeps busy; the plan checks them against the CPUs a
lane gets here, a warning under parallel measurement (validate, the dry run, the campaign's log) and a refusal under
`measurement: exclusive`, whose figures are taken for timing."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

import slamrun.methods
from slamrun.engine.spec_file import cpu_fit, load_spec
from slamrun.errors import SpecError
from tests.conftest import fake_method, write_spec

CPUS = len(os.sched_getaffinity(0))


def test_each_method_declares_the_threads_it_keeps_busy():
    threads = {name: cls({}).busy_threads() for name, cls in slamrun.methods.REGISTRY.items() if name != "external"}
    assert threads["orb_slam2"] == threads["orb_slam3"] == threads["df_orb_slam"] == threads["dynaslam"] == 3
    assert threads["dso"] == threads["ldso"] == threads["cnn_dso"] == 2 and threads["svo"] == 2
    assert threads["colmap"] is None and threads["glomap"] is None  # they take the CPUs of their lane
    assert slamrun.methods.get("dso")({"single_thread": True}).busy_threads() == 1  # nomt=1
    assert slamrun.methods.get("dsm")({}).busy_threads() == 1  # singleThreaded, its default
    assert slamrun.methods.get("dsm")({"single_threaded": False}).busy_threads() == 2


def spec_with(tmp_path, tiny_dataset, methods, **kw):
    return load_spec(write_spec(tmp_path, tiny_dataset, methods, **kw), check_files=False)


def test_more_threads_than_a_lane_has_is_a_warning_naming_the_lanes_that_fit(tmp_path, tiny_dataset):
    orb = {"name": "orb_slam3"}
    spec = spec_with(tmp_path, tiny_dataset, [fake_method(image="busybox"), orb], lanes=2, backend="docker")
    problems, warnings = cpu_fit(spec, cpus=4)  # 2 lanes of 2 CPUs: ORB-SLAM3's 3 threads wait
    assert problems == [] and len(warnings) == 1, warnings
    assert (
        "orb_slam3 keeps 3 threads busy" in warnings[0]
        and "each of the 2 lane(s) gets 2 of the 4 CPU(s)" in warnings[0]
    )
    assert "lanes: 1 gives each of its runs 3" in warnings[0]
    assert cpu_fit(spec, cpus=8) == ([], [])  # 2 lanes of 4 CPUs: it fits
    # 3 CPUs a lane fit its threads; the two lanes then share two of the 4 CPUs, which is said apart
    shared = cpu_fit(spec_with(tmp_path, tiny_dataset, [orb], lanes=2, cpus_per_lane=3, backend="docker"), 4)[1]
    assert len(shared) == 1 and shared[0].startswith("lanes share CPUs: 2 lanes of 3 CPU(s) need 6"), shared


def test_exclusive_measurement_refuses_a_method_with_more_threads_than_cpus(tmp_path, tiny_dataset):
    spec = spec_with(tmp_path, tiny_dataset, [{"name": "orb_slam2"}], measurement="exclusive", backend="docker")
    problems, warnings = cpu_fit(spec, cpus=2)
    assert warnings == [] and len(problems) == 1 and "methods[0]: orb_slam2 keeps 3 threads busy" in problems[0]
    assert "measurement: exclusive gives it the 2 CPU(s)" in problems[0]
    assert cpu_fit(spec, cpus=4) == ([], [])
    if CPUS < 3:  # this machine: the spec itself is refused when it would run here, naming the key's line
        with pytest.raises(SpecError, match=r"line \d+: methods\[0\]: orb_slam2 keeps 3 threads busy"):
            load_spec(write_spec(tmp_path, tiny_dataset, [{"name": "orb_slam2"}], measurement="exclusive",
                                 backend="docker"))  # fmt: skip


def test_validate_and_the_dry_run_say_it(tmp_path, tiny_dataset):
    spec = write_spec(tmp_path, tiny_dataset, [{"name": "orb_slam3"}], lanes=CPUS, backend="docker")
    for cmd in (["validate", str(spec)], ["plan", str(spec)]):
        out = subprocess.run([sys.executable, "-m", "slamrun.cli", *cmd], capture_output=True, text=True)
        assert out.returncode == 0, out.stdout + out.stderr
        assert "warning: orb_slam3 keeps 3 threads busy" in " ".join(out.stdout.split()), out.stdout
