"""Campaigns on a real Slurm cluster (one node on 127.0.0.1) through dask-jobqueue: workers as jobs, a job
cancelled mid-run, the checks before any run, and jobs that never start."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import psutil
import pytest

from slamrun.backends.jobqueue import job_name
from slamrun.datasets.make_synthetic import generate
from slamrun.engine.campaign import run_campaign
from slamrun.engine.spec_file import load_spec
from slamrun.errors import InfraError, SpecError
from tests import slurm_cluster
from tests.conftest import fake_method, write_spec
from tests.test_campaign import ledger_rows

pytest.importorskip("dask_jobqueue", reason="dask-jobqueue is not installed (make install gets it)")


@pytest.fixture(scope="module")
def slurm():
    why = slurm_cluster.missing()
    if why:
        if os.environ.get("CI"):
            pytest.fail(f"CI installs Slurm (.ci/run), yet: {why}")
        pytest.skip(reason=f"no single-node Slurm here ({why}); .ci/run installs slurm-wlm and munge")
    cluster = slurm_cluster.SlurmCluster().start()
    before = os.environ.get("SLURM_CONF")
    os.environ["SLURM_CONF"] = cluster.env["SLURM_CONF"]
    try:
        yield cluster
    finally:
        if before is None:
            os.environ.pop("SLURM_CONF", None)
        else:
            os.environ["SLURM_CONF"] = before
        cluster.stop()


@pytest.fixture(scope="module")
def rooms(tmp_path_factory) -> Path:
    """Two synthetic sequences the reference VO initialises and tracks on (a few seconds a run)."""
    root = tmp_path_factory.mktemp("rooms")
    generate(root / "seq_a", frames=120, seed=1, size=(320, 240))
    generate(root / "seq_b", frames=120, seed=2, size=(320, 240))
    return root


def slurm_spec(
    tmp_path: Path, dataset: Path, methods: list[dict] | None = None, trials: int = 2, **distributed
) -> Path:
    cluster = {
        "cluster": "slurm",
        "queue": "debug",
        "cores": 1,
        "memory": "1GB",
        "walltime": "00:30:00",
        "interface": "lo",  # scheduler and workers on loopback
        "min_workers": 2,
        "max_workers": 2,
        "worker_wait_s": 120,
    } | distributed
    return write_spec(
        tmp_path,
        dataset,
        methods or [{"name": "reference_vo"}],
        trials=trials,
        lanes=2,
        timeout_s=300,
        distributed=cluster,
    )


def our_jobs(slurm, results: Path) -> list[tuple[str, str, str]]:
    return [j for j in slurm.jobs() if j[1] == job_name(results)]


REPLACEMENT_DEADLINE_S = 120  # the test gives up waiting for a job replacing the cancelled one (and fails)


def test_a_campaign_runs_on_slurm_jobs_and_a_cancelled_job_costs_no_run(tmp_path, rooms, slurm):
    """A job scancelled mid-run is replaced by a new job and its run redone; no run is lost or written twice.

    Every run holds its result until the test releases it. The test cancels a job once both jobs' runs have
    started, and releases the runs once a job replacing it runs and the cancelled job's run process has ended
    with its job (a worker given SIGTERM may still finish its run within Slurm's KillWait, which would be a valid
    result, not a lost one): so that run is lost and redone, and the campaign cannot end before the replacement
    is due, however fast the runs are on this machine
    (the cause of the earlier flakiness: on a fast machine the other job finished every run within dask's 15 s
    lost-worker timeout, before any replacement was submitted). Without a replacement the runs are released
    after REPLACEMENT_DEADLINE_S and the test fails."""
    release = tmp_path / "release"
    started = tmp_path / "pids.txt"
    method = fake_method(extra=["--wait-for", str(release), "--marker", str(started)])
    spec = load_spec(slurm_spec(tmp_path, rooms, [method]))
    results = spec.results
    seen: set[str] = set()
    cancelled: list[str] = []
    before_cancel: set[str] = set()
    timing: dict[str, float] = {"start": time.monotonic()}
    stop = threading.Event()

    def running_processes() -> dict[str, int]:  # run staging folder -> its method's pid, once started
        found = {}
        for txt in results.rglob("process.txt") if results.exists() else []:
            try:
                found[str(txt.parent)] = int(txt.read_text().split()[1])
            except (OSError, IndexError, ValueError):  # being written or removed at this instant
                pass
        return found

    def dead(pid: int) -> bool:
        try:
            return psutil.Process(pid).status() == psutil.STATUS_ZOMBIE
        except psutil.NoSuchProcess:
            return True

    held: dict[str, int] = {}

    def watch_cancel_release() -> None:
        while not stop.is_set():
            jobs = [j for j in our_jobs(slurm, results) if j[2] == "RUNNING"]
            seen.update(j[0] for j in jobs)
            now = time.monotonic()
            if not cancelled and len(jobs) == 2 and len(running := running_processes()) == 2:
                held.update(running)  # both jobs hold a started run (held until released): one job is cancelled
                before_cancel.update(seen)
                slurm.run("scancel", jobs[0][0])
                cancelled.append(jobs[0][0])
                timing["cancelled"] = now
            replaced = cancelled and any(j[0] not in before_cancel for j in jobs)
            if replaced and "replaced" not in timing:
                timing["replaced"] = now
            if held and "killed" not in timing and any(dead(pid) for pid in held.values()):
                timing["killed"] = now  # the cancelled job's run ended with its job: it cannot finish there
            too_long = now - timing.get("cancelled", timing["start"]) > REPLACEMENT_DEADLINE_S
            if (("replaced" in timing and "killed" in timing) or too_long) and not release.exists():
                release.touch()
            time.sleep(0.2)

    watcher = threading.Thread(target=watch_cancel_release, daemon=True)
    watcher.start()
    try:
        res = run_campaign(spec, on_event=None)
    finally:
        stop.set()
        watcher.join()
        release.touch()
    rows = ledger_rows(res.results)
    assert len(rows) == 8  # 2 sequences x 2 directions x 2 trials, each once
    assert [r["status"] for r in rows] == ["done"] * 8, [(r["status"], r["message"]) for r in rows]
    assert cancelled, f"no job was cancelled mid-run (jobs seen: {sorted(seen)})"
    assert any(r["attempts"] > 1 for r in rows), f"the cancelled job's run was not retried ({timing}, {cancelled})"
    assert "replaced" in timing, (
        f"no job replaced the cancelled one within {REPLACEMENT_DEADLINE_S} s: {sorted(seen)} (cancelled {cancelled})"
    )
    print(f"replacement job running {timing['replaced'] - timing['cancelled']:.1f} s after the scancel")
    pids = [int(line.split()[0]) for line in started.read_text().splitlines()]
    alive = [p for p in pids if psutil.pid_exists(p) and psutil.Process(p).status() != "zombie"]
    assert len(pids) >= 8 and not alive, f"processes of runs outlived the campaign: {alive}"  # the cancelled one too
    finished = sorted(res.results.glob("runs/*/*/*/*/run.json"))
    assert len(finished) == 8, finished  # one folder per run: none written twice, no half-written one left
    machines = [json.loads(f.read_text())["machine"] for f in finished]  # each run names the node Slurm gave it
    assert all(m["slurm_node"] and m["slurm_job"] and m["name"] for m in machines), machines
    assert our_jobs(slurm, results) == []  # the campaign cancelled its jobs at the end


def test_a_job_left_by_a_crashed_start_is_cancelled_by_the_next(tmp_path, rooms, slurm):
    spec = load_spec(slurm_spec(tmp_path, rooms, trials=1, min_workers=1, max_workers=1))
    spec.results.mkdir(parents=True)
    left = slurm.run("sbatch", "--parsable", "-J", job_name(spec.results), "--wrap", "sleep 600").stdout.strip()
    deadline = time.monotonic() + 30
    while left not in [j[0] for j in slurm.jobs()] and time.monotonic() < deadline:
        time.sleep(0.2)
    res = run_campaign(spec, on_event=None)
    assert [r["status"] for r in ledger_rows(res.results)] == ["done"] * 4
    assert left not in [j[0] for j in slurm.jobs()]


def test_no_sbatch_on_path_is_said_before_any_run(tmp_path, rooms, slurm, monkeypatch):
    python_only = tmp_path / "bin"
    python_only.mkdir()
    (python_only / "python").symlink_to(sys.executable)
    monkeypatch.setenv("PATH", str(python_only))
    spec = load_spec(slurm_spec(tmp_path, rooms))
    with pytest.raises(InfraError, match=r"missing: sbatch, squeue, scancel, sinfo.*login node"):
        run_campaign(spec, on_event=None)
    assert {r["status"] for r in ledger_rows(spec.results)} == {"pending"}


def test_a_partition_that_does_not_exist_is_named_with_the_ones_that_do(tmp_path, rooms, slurm):
    spec = load_spec(slurm_spec(tmp_path, rooms, queue="gpu-large"))
    with pytest.raises(InfraError, match=r"no partition 'gpu-large' \(it has: debug\)"):
        run_campaign(spec, on_event=None)
    assert our_jobs(slurm, spec.results) == []


def test_a_job_slurm_cannot_satisfy_is_refused_before_it_is_queued(tmp_path, rooms, slurm):
    spec = load_spec(slurm_spec(tmp_path, rooms, memory="500GB"))
    with pytest.raises(InfraError, match=r"Slurm refuses the worker job.*node configuration is not available"):
        run_campaign(spec, on_event=None)
    assert our_jobs(slurm, spec.results) == []
    assert {r["status"] for r in ledger_rows(spec.results)} == {"pending"}


def test_jobs_that_stay_pending_end_the_wait_with_slurms_reason(tmp_path, rooms, slurm):
    spec = load_spec(slurm_spec(tmp_path, rooms, job_directives=["--begin=now+3600"], worker_wait_s=8, min_workers=1))
    t0 = time.monotonic()
    with pytest.raises(InfraError, match=r"no worker job started within .* 8 s: job \d+ pending \(BeginTime\)"):
        run_campaign(spec, on_event=None)
    assert time.monotonic() - t0 < 60
    assert our_jobs(slurm, spec.results) == []  # cancelled, not left queued
    assert {r["status"] for r in ledger_rows(spec.results)} == {"pending"}


def test_a_walltime_shorter_than_a_run_is_a_spec_error(tmp_path, tiny_dataset):
    path = write_spec(
        tmp_path,
        tiny_dataset,
        [{"name": "reference_vo"}],
        timeout_s=1800,
        distributed={"cluster": "slurm", "walltime": "00:30:00"},
    )
    with pytest.raises(SpecError, match=r"walltime 00:30:00 \(1800 s\) is shorter than one run may take"):
        load_spec(path)


def test_address_and_cluster_are_one_or_the_other(tmp_path, tiny_dataset):
    for distributed in ({"cluster": "slurm", "address": "tcp://h:8786"}, {"engine": "dask"}):
        path = write_spec(tmp_path, tiny_dataset, [{"name": "reference_vo"}], distributed=distributed)
        with pytest.raises(SpecError, match="either address .* or cluster"):
            load_spec(path)


def test_ctrl_c_cancels_the_jobs(tmp_path, rooms, slurm):
    path = slurm_spec(tmp_path, rooms, min_workers=1, max_workers=1)
    results = load_spec(path).results
    proc = subprocess.Popen(
        [sys.executable, "-m", "slamrun.cli", "campaign", str(path)],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        env={**os.environ, **slurm.env},
    )
    deadline = time.monotonic() + 120
    while not [j for j in our_jobs(slurm, results) if j[2] == "RUNNING"] and time.monotonic() < deadline:
        time.sleep(0.2)
    assert our_jobs(slurm, results), "no job started"
    proc.send_signal(2)
    out, _ = proc.communicate(timeout=120)
    assert "Traceback" not in out.decode(), out.decode()[-3000:]
    assert our_jobs(slurm, results) == []
