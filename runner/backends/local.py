"""Local backend: the method's argv as a process tree on this machine, pinned to the lane's CPUs."""

from __future__ import annotations

import os
import signal
import subprocess
import threading
import time

import psutil

from runner.backends.base import ExecRequest, ExecResult, supervise
from runner.errors import InfraError
from runner.logcap import CappedLog
from runner.monitor import Gpu, ProcessTreeMonitor

KILL_GRACE_S = 3.0


class LocalBackend:
    name = "local"

    def __init__(self, sample_interval_s: float = 0.5):
        self.sample_interval_s = sample_interval_s
        self.gpu = Gpu()

    def check(self, images: dict[str, str | None] | None = None) -> None:
        """Nothing to reach: a local process always has a machine to run on."""

    def process_paths(self, view, workdir):
        """A local process sees the host paths."""
        return view, workdir

    def execute(self, req: ExecRequest, cancel: threading.Event, on_start=None) -> ExecResult:
        cpus = req.cpus

        def pin() -> None:  # runs in the child between fork and exec
            if cpus:
                os.sched_setaffinity(0, cpus)

        env = {**os.environ, **req.env}
        log = CappedLog(req.log_path, req.log_cap_bytes)
        t0 = time.monotonic()
        try:
            proc = subprocess.Popen(
                req.argv,
                cwd=req.workdir,
                stdin=subprocess.DEVNULL,
                stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT,
                start_new_session=True,
                preexec_fn=pin,
                env=env,
            )
        except (FileNotFoundError, PermissionError) as exc:
            log.close()
            raise InfraError(f"cannot start {req.argv[0]!r}: {exc}; check the method's executable") from None
        pump = log.pump(proc.stdout)
        monitor = ProcessTreeMonitor(proc.pid, self.sample_interval_s, self.gpu).start()
        if on_start:
            on_start(proc.pid, psutil.Process(proc.pid).create_time())

        def step(remaining: float) -> bool:
            try:
                proc.wait(timeout=min(0.05, remaining))
                return True
            except subprocess.TimeoutExpired:
                return False

        timed_out, cancelled = supervise(step, t0, req.timeout_s, cancel)
        if timed_out or cancelled:
            kill_tree(proc, monitor.descendants())
        exit_code = proc.wait()
        wall_s = time.monotonic() - t0
        kill_tree(proc, monitor.descendants())  # children left behind by a finished parent
        series = monitor.stop()
        pump.join(timeout=5)
        proc.stdout.close()
        log.close()
        series.write_csv(req.resources_path)
        return ExecResult(
            exit_code=exit_code,
            wall_s=wall_s,
            timed_out=timed_out,
            cancelled=cancelled,
            log_truncated=log.truncated,
            resources=series.summary(wall_s, req.view.n_frames),
        )


def kill_tree(proc: subprocess.Popen, known: list[psutil.Process]) -> None:
    """SIGTERM the process group and every known descendant, then SIGKILL what is left."""
    procs = [p for p in known if p.pid != os.getpid()]
    for sig in (signal.SIGTERM, signal.SIGKILL):
        try:
            os.killpg(proc.pid, sig)
        except (ProcessLookupError, PermissionError):
            pass
        for p in procs:
            try:
                p.send_signal(sig)
            except psutil.Error:
                pass
        if sig == signal.SIGTERM:
            _, alive = psutil.wait_procs(procs, timeout=KILL_GRACE_S) if procs else ([], [])
            if not alive and proc.poll() is not None:
                break
            try:
                proc.wait(timeout=0.2)
            except subprocess.TimeoutExpired:
                pass


def kill_stale(pid: int, pid_start: float | None) -> bool:
    """Kill a process group left by a killed runner, if that PID is still the same process."""
    try:
        p = psutil.Process(pid)
        if pid_start is not None and abs(p.create_time() - pid_start) > 0.01:
            return False
        group = [q for q in psutil.process_iter() if _pgid(q.pid) == pid]
        for q in group:
            q.kill()
        psutil.wait_procs(group, timeout=3)
        return True
    except psutil.Error:
        return False


def _pgid(pid: int) -> int | None:
    try:
        return os.getpgid(pid)
    except OSError:
        return None
