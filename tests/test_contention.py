"""What a run's FPS and CPU figures were taken beside: the time its threads waited for a CPU and the machine's CPU
pressure over the run, measured on real processes sharing a CPU with a real hog. The busy loop's own clocks are
the truth: a thread that never sleeps is ready to run all along, so the time it waited is its wall time less its
CPU time, whatever else the machine runs (these tests hold on a loaded machine too)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from slamrun.backends.monitor import HOST_PRESSURE, ProcessTreeMonitor
from tests.conftest import fake_method, one_sequence, write_spec

BUSY = """import time
t0, c0 = time.monotonic(), time.process_time()
while time.monotonic() - t0 < {seconds}:
    pass
print(time.monotonic() - t0, time.process_time() - c0)
"""


def pinned(cpu: int):
    return lambda: os.sched_setaffinity(0, {cpu})


def monitored(code: str, cpu: int) -> tuple[str, object]:
    """`code` run by Python on CPU `cpu`, sampled every 0.1 s: (its stdout, its resource series)."""
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True, preexec_fn=pinned(cpu))
    monitor = ProcessTreeMonitor(proc.pid, 0.1).start()
    out, _ = proc.communicate(timeout=120)
    return out, monitor.stop()


@pytest.fixture
def hog_on_one_cpu():
    """A busy process pinned to this process's first CPU: (that CPU)."""
    cpu = sorted(os.sched_getaffinity(0))[0]
    hog = subprocess.Popen([sys.executable, "-c", "while True: pass"], preexec_fn=pinned(cpu))
    try:
        yield cpu
    finally:
        hog.kill()
        hog.wait()


def test_a_busy_thread_sharing_its_cpu_waits_its_wall_time_less_its_cpu_time(hog_on_one_cpu):
    out, series = monitored(BUSY.format(seconds=3.0), hog_on_one_cpu)
    wall, cpu = map(float, out.split())
    assert wall - cpu > 0.3 * wall  # the hog took about half its CPU
    # its wait before the loop (Python's start) is in the measure, not in its clocks: a few hundredths of a second
    assert series.waited_s == pytest.approx(wall - cpu, abs=0.1 * wall)
    if HOST_PRESSURE.exists():  # the machine was under pressure at least while this loop waited
        # Linux's machine-wide "some" weighs each CPU by its busy time: the loop's CPU, contended while it waited, is
        # at least 1/n of it on n CPUs (all of it on a machine otherwise idle; half on 2 CPUs whose other one is busy)
        share = (wall - cpu) / (os.cpu_count() or 1)
        assert series.host_pressure_s >= 0.8 * share
        assert series.summary(wall, None)["host_cpu_pressure_pct"] >= 80 * share / wall


def test_a_sleeping_process_waits_for_no_cpu_beside_the_same_hog(hog_on_one_cpu):
    _, series = monitored("import time; time.sleep(2.0)", hog_on_one_cpu)
    assert series.waited_s is not None and series.waited_s < 0.5  # its start only, not its 2 s asleep


def test_every_run_records_its_wait_and_the_machines_pressure(tmp_path: Path, tiny_dataset):
    from slamrun.analysis.tables import resources_table
    from slamrun.engine.campaign import run_campaign
    from slamrun.engine.spec_file import load_spec

    spec = write_spec(tmp_path, tiny_dataset, [fake_method(sleep=0.5)], datasets=one_sequence(tiny_dataset))
    res = run_campaign(load_spec(spec), on_event=None)
    df = pd.read_csv(res.results_csv)
    assert (df.status == "done").all() and df.cpu_wait_pct.notna().all() and (df.cpu_wait_pct >= 0).all()
    if HOST_PRESSURE.exists():
        assert df.host_cpu_pressure_pct.between(0, 100.5).all()
    table = resources_table(df.assign(method=df.get("method", "external")))
    assert "CPU wait %" in table.columns and "machine CPU pressure %" in table.columns
