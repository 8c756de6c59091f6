"""Local backend: the method's argv as a process tree on this machine, pinned to the lane's CPUs."""

from __future__ import annotations

import os
import signal
import subprocess
import threading
import time
import uuid

import psutil

from slamrun.backends.base import Defaults, ExecRequest, ExecResult, OutputWatch, supervise, supervised_result
from slamrun.backends.logcap import CappedLog
from slamrun.backends.monitor import Gpu, ProcessTreeMonitor, exited
from slamrun.errors import InfraError

KILL_GRACE_S = 3.0
PUMP_DRAIN_S = 2.0
TOKEN_VAR = "SLAMRUN_RUN_TOKEN"  # in the environment of every process a run starts


class LocalBackend(Defaults):
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

        token = req.token or uuid.uuid4().hex  # every process of the run inherits it, however it detaches
        env = {**os.environ, **req.env, TOKEN_VAR: token}
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
        pump_stop = threading.Event()
        pump = log.pump(proc.stdout, pump_stop)
        monitor = ProcessTreeMonitor(proc.pid, self.sample_interval_s, self.gpu).start()
        if on_start:
            on_start(proc.pid, psutil.Process(proc.pid).create_time())

        def step(remaining: float) -> bool:
            return exited(proc.pid, min(0.05, remaining))  # not reaped yet: its last figures stay readable

        timed_out, cancelled, exceeded = supervise(step, t0, req.timeout_s, cancel, OutputWatch.of(req))
        if timed_out or cancelled or exceeded:
            kill_tree(proc, monitor.descendants() + processes_with_token(token))
        exited(proc.pid)
        monitor.sample()  # the exited process's last figures (its wait up to its end), read before it is reaped
        exit_code = proc.wait()
        wall_s = time.monotonic() - t0
        # every process of the run ends with it: children left by a finished parent, in its group or not
        kill_tree(proc, monitor.descendants() + processes_with_token(token))
        series = monitor.stop()
        pump.join(timeout=PUMP_DRAIN_S)  # the rest of the output, once its writers are gone
        pump_stop.set()
        pump.join(timeout=PUMP_DRAIN_S)
        if not pump.is_alive():
            proc.stdout.close()
        log.close()
        return supervised_result(req, series, exit_code, wall_s, (timed_out, cancelled, exceeded), log.truncated)


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


def kill_processes(procs: list[psutil.Process]) -> int:
    """SIGKILL these processes and wait for them; returns how many there were."""
    for p in procs:
        try:
            p.kill()
        except psutil.Error:
            pass
    psutil.wait_procs(procs, timeout=3)
    return len(procs)


def processes_with_token(token: str) -> list[psutil.Process]:
    """Processes whose environment holds this run's token: its descendants, even those that left its
    process group and session and were re-parented (a process that clears its environment escapes)."""
    needle = f"{TOKEN_VAR}={token}".encode()
    found = []
    for entry in os.scandir("/proc"):
        if not entry.name.isdigit() or int(entry.name) == os.getpid():
            continue
        try:
            with open(f"/proc/{entry.name}/environ", "rb") as f:
                if needle in f.read():
                    found.append(psutil.Process(int(entry.name)))
        except (OSError, psutil.Error):
            continue
    return found


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
