"""The engine end to end with real processes: results, failures as data, timeouts, lock, signals, resume."""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import sqlite3
import subprocess
import sys
import threading
import time
from pathlib import Path

import pandas as pd
import psutil
import pytest

from slamrun.backends.local import LocalBackend
from slamrun.engine.campaign import run_campaign
from slamrun.engine.ledger import ResultsLock
from slamrun.engine.spec_file import load_spec
from slamrun.errors import InfraError
from tests.conftest import fake_method, mount_tmpfs, one_sequence, write_spec

REQUIRED_COLUMNS = (
    "method, sequence, direction, trial, status, failure, e_t, e_r, e_s, e_align, e_start, e_end, "
    "e_rmse, n_poses, wall_s, fps, cpu_mean_pct, cpu_peak_pct, ram_peak_mb, gpu_mem_peak_mb"
).split(", ")


def campaign(spec_path: Path, **kw):
    return run_campaign(load_spec(spec_path), log=lambda *a: None, **kw)


def ledger_rows(results: Path) -> list[dict]:
    if not (results / "ledger.sqlite").exists():
        return []
    db = sqlite3.connect(f"file:{results / 'ledger.sqlite'}?mode=ro", uri=True, timeout=10)
    db.row_factory = sqlite3.Row
    try:
        return [dict(r) for r in db.execute("SELECT * FROM runs")]
    except sqlite3.OperationalError:  # not created yet
        return []
    finally:
        db.close()


def slamrun(*args: str) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "slamrun.cli", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )


def test_results_layout_and_evaluation(tmp_path, tiny_dataset):
    spec = write_spec(tmp_path, tiny_dataset, [fake_method()], trials=2)
    res = campaign(spec)
    assert res.counts["done"] == 8 and res.infra_failures == 0
    df = pd.read_csv(res.results_csv)
    assert set(REQUIRED_COLUMNS) <= set(df.columns)
    assert pd.read_parquet(res.results / "results.parquet").shape == df.shape
    # The fake method writes the ground truth (scaled and shifted): every error ~0, backward included.
    assert (df.eval_status == "ok").all()
    assert df.e_align.max() < 1e-6 and df.e_rmse.max() < 1e-6 and (df.e_s - 1).abs().max() < 1e-6
    assert set(df.direction) == {"forward", "backward"}
    assert df.gpu_mem_peak_mb.isna().all()  # no GPU: empty, never zero
    run_dir = Path(df.run_dir[0])
    assert {"trajectory.txt", "log.txt", "resources.csv", "run.json", "raw"} <= {p.name for p in run_dir.iterdir()}
    assert run_dir.relative_to(res.results).parts[0] == "runs"
    # trajectory.txt carries the ORIGINAL timestamps, increasing, also for backward runs
    back = df[df.direction == "backward"].iloc[0]
    traj = pd.read_csv(Path(back.run_dir) / "trajectory.txt", sep=" ", comment="#", header=None)
    times = pd.read_csv(tiny_dataset / back.sequence / "times.txt", sep=" ", header=None)[1]
    assert traj[0].is_monotonic_increasing and abs(traj[0].iloc[0] - times.iloc[0]) < 1e-6
    # A second start finds nothing to do and touches nothing.
    mtime = (run_dir / "run.json").stat().st_mtime_ns
    res2 = campaign(spec)
    assert res2.added == 0 and res2.counts["done"] == 8
    assert (run_dir / "run.json").stat().st_mtime_ns == mtime


def test_method_failures_are_data(tmp_path, tiny_dataset):
    methods = [
        fake_method("crash", label="crash"),
        fake_method("garbage", label="garbage"),
        fake_method("nothing", label="nothing"),
        fake_method("empty", label="empty", not_initialized_pattern=r"^NOT INITIALIZED"),
        fake_method("lost", label="lost", lost_pattern=r"^LOST"),
    ]
    spec = write_spec(tmp_path, tiny_dataset, methods, directions=["forward"])
    res = campaign(spec)
    df = pd.read_csv(res.results_csv).set_index("method")
    assert res.infra_failures == 0
    assert (df.status == "failed").all()
    assert set(df.loc["crash", "failure"]) == {"crashed"}
    assert (df.loc["crash", "exit_code"] == 139).all()
    assert df.loc["crash", "message"].str.contains("Segmentation fault").all()  # the log tail
    assert set(df.loc["garbage", "failure"]) == {"no_output"}
    assert set(df.loc["nothing", "failure"]) == {"no_output"}
    assert set(df.loc["empty", "failure"]) == {"not_initialized"}
    assert set(df.loc["lost", "failure"]) == {"lost"}
    assert (df.loc["lost", "n_poses"] > 0).all()  # what it tracked before it got lost is kept
    # attempts: method failures are never retried
    assert (df.attempts == 1).all()


def test_timeout_kills_the_whole_tree(tmp_path, tiny_dataset):
    marker = tmp_path / "pids.txt"
    spec = write_spec(
        tmp_path,
        tiny_dataset,
        [fake_method("child-hang", extra=["--marker", str(marker)])],
        timeout_s=1.5,
        directions=["forward"],
    )
    t0 = time.monotonic()
    res = campaign(spec)
    assert time.monotonic() - t0 < 30
    df = pd.read_csv(res.results_csv)
    assert (df.failure == "timeout").all() and (df.wall_s < 10).all()
    lines = [line.split() for line in marker.read_text().splitlines() if line]
    pids = [int(w[1]) if w[0] == "child" else int(w[0]) for w in lines]
    assert len(pids) == 4  # two runs: the method and its child each
    for pid in pids:
        assert not psutil.pid_exists(pid) or psutil.Process(pid).status() == psutil.STATUS_ZOMBIE


def test_log_flood_is_capped_and_run_recorded(tmp_path, tiny_dataset):
    spec = write_spec(
        tmp_path,
        tiny_dataset,
        [fake_method("flood")],
        log_cap_mb=1,
        directions=["forward"],
        datasets=one_sequence(tiny_dataset),
    )
    res = campaign(spec)
    df = pd.read_csv(res.results_csv)
    assert df.status.tolist() == ["done"]
    log = Path(df.run_dir[0]) / "log.txt"
    assert log.stat().st_size < 1.1 * 2**20
    text = log.read_text()
    assert "log capped" in text and text.rstrip().endswith("done")  # head, marker, and the tail kept
    assert json.loads((Path(df.run_dir[0]) / "run.json").read_text())["log_truncated"] is True


def test_resources_sampled(tmp_path, tiny_dataset):
    spec = write_spec(
        tmp_path,
        tiny_dataset,
        [fake_method("burn", sleep=2.0)],
        directions=["forward"],
        lanes=1,
        datasets=one_sequence(tiny_dataset),
    )
    res = campaign(spec)
    row = pd.read_csv(res.results_csv).iloc[0]
    series = pd.read_csv(Path(row.run_dir) / "resources.csv")
    assert len(series) >= 4  # >= 2 Hz over ~2 s
    # the CPU the process really got (its own process_time: less than a core when the machine is loaded); the
    # sampled peak is at least the mean over its burn
    burnt = re.search(r"burnt cpu_s=([\d.]+) in wall_s=([\d.]+)", (Path(row.run_dir) / "log.txt").read_text())
    got_pct = 100 * float(burnt[1]) / float(burnt[2])
    assert got_pct > 5 and row.cpu_peak_pct > 0.8 * got_pct, (row.cpu_peak_pct, got_pct)
    assert row.ram_peak_mb > 5 and row.wall_s >= 2.0
    assert row.fps == pytest.approx(40 / row.wall_s)


def test_second_runner_is_refused(tmp_path, tiny_dataset):
    spec = write_spec(tmp_path, tiny_dataset, [fake_method()])
    with ResultsLock(tmp_path / "results"):
        proc = slamrun("campaign", str(spec))
        out, err = proc.communicate(timeout=60)
    assert proc.returncode == 1
    assert f"PID {os.getpid()}" in err and "another slamrun" in err


class FlakyBackend(LocalBackend):
    """Raises an infrastructure error for the first `fail` calls, then runs for real."""

    def __init__(self, fail: int):
        super().__init__()
        self.fail = fail
        self.calls = 0
        self.lock = threading.Lock()

    def execute(self, req, cancel, on_start=None):
        with self.lock:
            self.calls += 1
            if self.calls <= self.fail:
                raise InfraError("docker daemon gone (simulated)")
        return super().execute(req, cancel, on_start)


def one_run_spec(tmp_path: Path, dataset: Path, retries: int) -> Path:
    """A spec with a single run (one sequence, forward, one trial) of the fake method."""
    return write_spec(
        tmp_path,
        dataset,
        [fake_method()],
        directions=["forward"],
        lanes=1,
        retries=retries,
        datasets=one_sequence(dataset),
    )


def test_infra_failures_are_retried(tmp_path, tiny_dataset):
    spec = one_run_spec(tmp_path, tiny_dataset, retries=2)
    backend = FlakyBackend(fail=2)
    res = campaign(spec, backend=backend)
    df = pd.read_csv(res.results_csv)
    assert df.status.tolist() == ["done"] and df.attempts.tolist() == [3] and backend.calls == 3


def test_infra_give_up_then_retry_next_start(tmp_path, tiny_dataset):
    spec = one_run_spec(tmp_path, tiny_dataset, retries=1)
    res = campaign(spec, backend=FlakyBackend(fail=100))
    df = pd.read_csv(res.results_csv)
    assert df.failure.tolist() == ["infra"] and "daemon gone" in df.message[0] and res.infra_failures == 1
    res2 = campaign(spec, backend=FlakyBackend(fail=0))
    assert res2.recovered["infra_reset"] == 1 and res2.counts["done"] == 1 and res2.infra_failures == 0


def _wait_for(cond, timeout=60.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(0.05)
    return False


def _snapshot(run_dir: Path) -> dict:
    return {p.relative_to(run_dir): (p.stat().st_mtime_ns, p.read_bytes()) for p in run_dir.rglob("*") if p.is_file()}


def test_kill_9_then_resume(tmp_path, tiny_dataset):
    marker = tmp_path / "starts.txt"
    spec = write_spec(tmp_path, tiny_dataset, [fake_method(sleep=0.8, extra=["--marker", str(marker)])], trials=3)
    results = tmp_path / "results"
    proc = slamrun("campaign", str(spec))

    def mid_way():
        rows = ledger_rows(results)
        return sum(r["status"] == "done" for r in rows) >= 3 and any(r["status"] == "running" for r in rows)

    assert _wait_for(mid_way), proc.communicate(timeout=5)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    rows = ledger_rows(results)
    finished = {r["key"]: Path(r["run_dir"]) for r in rows if r["status"] == "done"}
    in_flight = [r for r in rows if r["status"] == "running"]
    assert finished and in_flight
    before = {k: _snapshot(d) for k, d in finished.items()}

    proc2 = slamrun("campaign", str(spec))
    out, err = proc2.communicate(timeout=120)
    assert proc2.returncode == 0, err
    rows = ledger_rows(results)
    assert len(rows) == 12 and all(r["status"] == "done" for r in rows)
    for key, run_dir in finished.items():  # finished runs untouched, never executed again
        assert _snapshot(run_dir) == before[key]
        assert json.loads((run_dir / "run.json").read_text())["attempt"] == 1
    for r in in_flight:  # interrupted runs were redone
        assert json.loads((Path(r["run_dir"]) / "run.json").read_text())["attempt"] == 2
    assert sorted(p.name for p in (results / "runs").rglob("run.json")).count("run.json") == 12
    assert not list((results / "runs").rglob(".*.tmp-*"))
    # each run that finished before the kill was started exactly once; every run at least once
    starts = [line.split()[1] for line in marker.read_text().splitlines() if line]

    def run_of(out: str) -> str:  # .../<sequence>/<direction>/.<trial>.tmp-<attempt>/raw/trajectory.txt
        parts = Path(out).parts
        return "/".join((parts[-5], parts[-4], parts[-3].split(".")[1]))

    counts = {}
    for out in starts:
        counts[run_of(out)] = counts.get(run_of(out), 0) + 1
    assert len(counts) == 12
    for key in finished:
        assert counts["/".join(key.split("/")[1:])] == 1, key


def test_sigint_stops_cleanly_and_resumes(tmp_path, tiny_dataset):
    spec = write_spec(tmp_path, tiny_dataset, [fake_method(sleep=1.5)], trials=2, stop_grace_s=0.5)
    results = tmp_path / "results"
    proc = slamrun("campaign", str(spec))
    assert _wait_for(lambda: any(r["status"] == "running" for r in ledger_rows(results)))
    t0 = time.monotonic()
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert time.monotonic() - t0 < 15
    assert proc.returncode == 130, err
    assert "resume" in out
    rows = ledger_rows(results)
    assert not any(r["status"] == "running" for r in rows)
    assert any(r["status"] == "pending" for r in rows)
    for r in rows:
        if r["status"] == "done":
            assert (Path(r["run_dir"]) / "trajectory.txt").exists()
    proc2 = slamrun("campaign", str(spec))
    proc2.communicate(timeout=120)
    assert all(r["status"] == "done" for r in ledger_rows(results))


def test_ctrl_c_after_which_every_run_finished_says_so_and_writes_the_report(tmp_path, tiny_dataset):
    """SIGINT while the last runs run, which then finish within the grace period: nothing is left to resume, so
    it said "stopped before the end" and wrote no report. It says the campaign is complete, writes the report and
    exits 0."""
    spec = write_spec(
        tmp_path, tiny_dataset, [fake_method(sleep=2.0)], datasets=one_sequence(tiny_dataset), report=True
    )
    results = tmp_path / "results"
    proc = slamrun("campaign", str(spec))
    # both runs (forward, backward) on the two lanes: nothing pending, so the stop can only let them finish
    assert _wait_for(lambda: sum(r["status"] == "running" for r in ledger_rows(results)) == 2)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 0, out + err
    assert all(r["status"] == "done" for r in ledger_rows(results))
    assert "stopped before the end" not in out
    assert (
        "SIGINT came after the last runs had started; they finished within the grace period: the campaign is "
        "complete" in " ".join(out.split())
    )
    assert (results / "report" / "index.html").is_file() and "report: " in out


def test_status_cli(tmp_path, tiny_dataset):
    spec = write_spec(tmp_path, tiny_dataset, [fake_method(), fake_method("crash", label="crashy")])
    campaign(spec)
    proc = slamrun("status", str(tmp_path / "results"))
    out, _ = proc.communicate(timeout=60)
    assert proc.returncode == 0
    rows = [[c.strip() for c in line.strip("│ ").split("│")] for line in out.splitlines() if line.count("│") > 6]
    rate = {(r[0], r[1]): r[-2] for r in rows}  # success %, then the mean CPU wait of the finished runs
    assert rate[("crashy", "forward")] == "0" and rate[("external", "backward")] == "100"
    assert all(r[-1].isdigit() for r in rows if r[0] in ("crashy", "external")), rows
    assert "8/8" in out and "campaign not running" in out


@pytest.fixture
def small_disk(tmp_path):
    """A 48 MB tmpfs for the results directory (needs root; the CI machine is root)."""
    mount = mount_tmpfs(tmp_path / "disk", 48, "the full-disk test")
    yield mount
    subprocess.run(["umount", "-l", str(mount)], check=False)


def _fill(folder: Path) -> Path:
    """Write a file until the filesystem is full; returns it (delete it to free the space)."""
    filler = folder / "filler.bin"
    chunk = b"\0" * 2**20
    with open(filler, "wb") as f:
        try:
            while True:
                f.write(chunk)
                f.flush()
        except OSError:
            pass
    for n in range(4096, 0, -1):  # then the last bytes, so that nothing at all fits
        try:
            with open(filler, "ab") as f:
                f.write(b"\0" * n)
        except OSError:
            continue
    return filler


def test_full_disk_stops_keeps_finished_runs_and_resumes(tmp_path, tiny_dataset, small_disk):
    results = small_disk / "results"
    spec = write_spec(tmp_path, tiny_dataset, [fake_method(sleep=0.5)], trials=3, results=str(results))
    proc = slamrun("campaign", str(spec))
    assert _wait_for(lambda: sum(r["status"] == "done" for r in ledger_rows(results)) >= 3), proc.communicate(timeout=5)
    filler = _fill(small_disk)
    out, err = proc.communicate(timeout=120)  # it stops by itself, it does not hang
    assert proc.returncode != 0
    said = out + err
    assert "disk" in said.lower() and "full" in said.lower(), said[-2000:]
    assert "make campaign" in said or "again" in said, said[-2000:]
    rows = ledger_rows(results)
    assert len(rows) == 12
    assert not [r for r in rows if r["status"] == "failed"], [r["message"] for r in rows if r["status"] == "failed"]
    finished = {r["key"]: Path(r["run_dir"]) for r in rows if r["status"] == "done"}
    assert len(finished) >= 3
    before = {k: _snapshot(d) for k, d in finished.items()}

    filler.unlink()
    proc2 = slamrun("campaign", str(spec))
    out, err = proc2.communicate(timeout=180)
    assert proc2.returncode == 0, err
    rows = ledger_rows(results)
    assert len(rows) == 12 and all(r["status"] == "done" for r in rows), [(r["status"], r["message"]) for r in rows]
    for key, run_dir in finished.items():
        assert _snapshot(run_dir) == before[key]
    assert not list((results / "runs").rglob(".*.tmp-*"))


def test_full_disk_while_preparing_views_is_reported_then_resumes(tmp_path, tiny_dataset, small_disk):
    spec = write_spec(tmp_path, tiny_dataset, [fake_method()], cache=str(small_disk / "cache"))
    filler = _fill(small_disk)
    proc = slamrun("campaign", str(spec))
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 1
    assert "Traceback" not in err and "disk is full" in err and "again to resume" in err, err[-2000:]
    filler.unlink()
    proc = slamrun("campaign", str(spec))
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 0, err
    assert all(r["status"] == "done" for r in ledger_rows(tmp_path / "results"))


def test_dask_engine_runs_on_workers_and_stops_them(tmp_path, tiny_dataset):
    """A real Dask cluster (worker processes on 127.0.0.1): the runs execute in the workers, evaluate as
    usual, and a SIGINT stops runs in flight on the workers without leaving processes behind."""
    pytest.importorskip("distributed")
    marker = tmp_path / "starts.txt"
    spec = write_spec(
        tmp_path,
        tiny_dataset,
        [fake_method(sleep=0.2, extra=["--marker", str(marker)])],
        distributed={"engine": "dask", "address": "local"},
    )
    proc = slamrun("campaign", str(spec))
    out, err = proc.communicate(timeout=180)
    assert proc.returncode == 0, err[-3000:]
    rows = ledger_rows(tmp_path / "results")
    assert len(rows) == 4 and all(r["status"] == "done" and r["eval_status"] == "ok" for r in rows)
    records = [json.loads((Path(r["run_dir"]) / "run.json").read_text()) for r in rows]
    assert {rec["engine"] for rec in records} == {"dask"} and {rec["backend"] for rec in records} == {"local"}
    starts = [line.split() for line in marker.read_text().splitlines()]
    assert len(starts) == 4

    (tmp_path / "h").mkdir()
    hang = write_spec(
        tmp_path / "h",
        tiny_dataset,
        [fake_method("hang")],
        distributed={"engine": "dask", "address": "local"},
        stop_grace_s=0.5,
    )
    results = tmp_path / "h" / "results"
    proc = slamrun("campaign", str(hang))
    assert _wait_for(lambda: sum(r["status"] == "running" for r in ledger_rows(results)) == 2, timeout=120)
    assert _wait_for(lambda: len(_fake_processes("hang")) == 2, timeout=60)
    workers = {p.ppid() for p in _fake_processes("hang")}
    assert proc.pid not in workers  # started by the Dask workers
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err[-3000:]
    assert _wait_for(lambda: not _fake_processes("hang"), timeout=30)
    assert all(r["status"] == "pending" for r in ledger_rows(results))


def _fake_processes(mode: str) -> list[psutil.Process]:
    found = []
    for p in psutil.process_iter(["cmdline"]):
        cmd = p.info["cmdline"] or []
        if any(c.endswith("fake_method.py") for c in cmd) and mode in cmd:
            found.append(p)
    return found


def test_dask_engine_kill_9_then_the_next_start_kills_what_was_left(tmp_path, tiny_dataset):
    pytest.importorskip("distributed")
    engine = {"engine": "dask", "address": "local"}
    spec = write_spec(tmp_path, tiny_dataset, [fake_method("hang")], distributed=engine, timeout_s=4, trials=1)
    results = tmp_path / "results"
    proc = slamrun("campaign", str(spec))
    assert _wait_for(lambda: sum(bool(r["pid"]) for r in ledger_rows(results)) == 2, timeout=120)
    left = [p for p in _fake_processes("hang") if p.pid in {r["pid"] for r in ledger_rows(results)}]
    assert len(left) == 2
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    proc2 = slamrun("campaign", str(spec))
    assert _wait_for(lambda: not any(p.is_running() and p.status() != psutil.STATUS_ZOMBIE for p in left), 60)
    out, err = proc2.communicate(timeout=240)
    assert proc2.returncode == 0, err[-3000:]
    rows = ledger_rows(results)
    assert len(rows) == 4 and all(r["failure"] == "timeout" for r in rows)  # the hang method times out
    assert not _fake_processes("hang")


def test_a_run_on_a_worker_stops_when_its_staging_folder_disappears(tmp_path, tiny_dataset):
    """What a Dask worker does when the campaign machine crashed and its next start removed the attempt."""
    from slamrun.backends.base import ExecRequest
    from slamrun.backends.dask import _RemoteCancel
    from slamrun.datasets.cache import prepare
    from slamrun.datasets.view import Direction, Profile

    view = prepare(tiny_dataset / "seq_a", Direction.forward, Profile.native, tmp_path / "cache")
    stage = tmp_path / ".00.tmp-1"
    (stage / "raw").mkdir(parents=True)
    req = ExecRequest(
        argv=[sys.executable, "-c", "import time; time.sleep(60)"],
        workdir=stage / "raw",
        view=view,
        log_path=tmp_path / "log.txt",
        resources_path=tmp_path / "resources.csv",
        timeout_s=60,
    )
    threading.Timer(1.0, shutil.rmtree, args=(stage,)).start()
    t0 = time.monotonic()
    result = LocalBackend().execute(req, _RemoteCancel(stage / "cancel.flag"))
    assert result.cancelled and time.monotonic() - t0 < 15


def test_a_worker_that_cannot_see_the_results_folder_is_named(tmp_path):
    import socket

    from slamrun.backends.dask import _check_on_worker

    problem = _check_on_worker("local", None, str(tmp_path / "not-shared" / ".probe"))
    assert problem and socket.gethostname() in problem and "shared" in problem
    (tmp_path / ".probe").write_text("x")
    assert _check_on_worker("local", None, str(tmp_path / ".probe")) is None


def test_an_unreachable_dask_scheduler_is_named(tmp_path):
    pytest.importorskip("distributed")
    from slamrun.backends.dask import DaskBackend

    with pytest.raises(InfraError, match=r"cannot reach the Dask scheduler at tcp://127\.0\.0\.1:9"):
        DaskBackend("local", "tcp://127.0.0.1:9", tmp_path, connect_timeout_s=2)


def test_a_full_disk_on_a_finished_campaign_is_said_as_a_full_disk_by_every_command(tmp_path, tiny_dataset, small_disk):
    """A finished campaign's disk fills: `campaign` (nothing left to run) said "not a readable ledger (disk I/O
    error) ... move it aside" of a whole ledger, `report` and `import` ended in tracebacks. Now each says the disk is
    full in one line and exits 1; `status` reads as ever; the ledger and the runs are unchanged."""
    results = small_disk / "results"
    spec = write_spec(
        tmp_path,
        tiny_dataset,
        [fake_method()],
        datasets=one_sequence(tiny_dataset),
        trials=1,
        results=str(results),
        report=False,
    )
    out, err = slamrun("campaign", str(spec)).communicate(timeout=300)
    assert all(r["status"] == "done" for r in ledger_rows(results)), err
    run_dir = Path(ledger_rows(results)[0]["run_dir"])
    source = tmp_path / "published"
    source.mkdir()
    (source / "seq_a_fw_1.txt").write_bytes((run_dir / "trajectory.txt").read_bytes())
    before = kept(results)
    filler = _fill(small_disk)
    try:
        commands = {
            "campaign": ["campaign", str(spec)],
            "report": ["report", str(results)],
            "import": [
                "import",
                str(source),
                "--campaign",
                str(results),
                "--as",
                "lab:vo",
                "--pattern",
                r"(?P<sequence>seq_a)_(?P<direction>fw)_(?P<trial>\d+)\.txt",
            ],
        }
        for name, argv in commands.items():
            proc = slamrun(*argv)
            out, err = proc.communicate(timeout=300)
            assert proc.returncode == 1, (name, proc.returncode, err[-2000:])
            assert "Traceback" not in err and "disk is full" in err, (name, err[-2000:])
            assert "move it aside" not in err and "damaged" not in err, (name, err[-2000:])
        proc = slamrun("status", str(results))
        out, err = proc.communicate(timeout=120)
        assert proc.returncode == 0 and "done" in out, err
    finally:
        filler.unlink()
    assert kept(results) == before


def kept(results: Path) -> dict:
    """What a campaign keeps: the ledger and the runs (not the lock's PID, SQLite's -wal/-shm, the report)."""
    return {
        p.relative_to(results): p.read_bytes()
        for p in results.rglob("*")
        if p.is_file() and p.name != "runner.lock" and not p.name.endswith(("-wal", "-shm")) and "report" not in p.parts
    }


def test_concurrent_reports_of_one_campaign_are_written_one_after_the_other(tmp_path, tiny_dataset):
    """Three `slamrun report` of one campaign at once, twice: one in three such rounds ended in a FileNotFoundError
    traceback (one report clearing what another was writing). Now each waits for the one writing, and all end with
    a whole report."""
    spec = write_spec(tmp_path, tiny_dataset, [fake_method(extra=["--noise", "0.01", "--vary"])], trials=2)
    out, err = slamrun("campaign", str(spec)).communicate(timeout=300)
    results = tmp_path / "results"
    assert all(r["status"] == "done" for r in ledger_rows(results)), err
    for _ in range(2):
        procs = [slamrun("report", str(results)) for _ in range(3)]
        ends = [p.communicate(timeout=300) + (p.returncode,) for p in procs]
        for _out, err, code in ends:
            assert code == 0 and "Traceback" not in err, err[-2000:]
        index = (results / "report" / "index.html").read_text()
        assert index.rstrip().endswith("</html>") and "Provenance" in index


def test_a_results_folder_belongs_to_the_campaign_that_made_it(tmp_path: Path, tiny_dataset):
    """A second spec with another name and the same results folder is refused before any run, naming both campaigns
    and what to do; the first campaign's results are untouched."""
    spec = write_spec(tmp_path, tiny_dataset, [fake_method("ok", label="a")], evaluate=False)
    run_campaign(load_spec(spec), on_event=None)
    before = (tmp_path / "results" / "results.csv").read_bytes()
    other = write_spec(tmp_path, tiny_dataset, [fake_method("ok", label="a")], evaluate=False, name="other")
    with pytest.raises(Exception, match=r"holds the results of campaign 't', and this spec is campaign 'other'"):
        load_spec(other)
    assert (tmp_path / "results" / "results.csv").read_bytes() == before
