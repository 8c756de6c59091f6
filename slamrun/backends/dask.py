"""Distributed engine: each run's process is started by a Dask worker (on another machine, or on this one).

The scheduler, the ledger and every file decision stay on this machine; a worker only runs the method's
process with the local or Docker backend and writes its log and resources.csv. So the results directory
and the view cache must be on a filesystem all workers see at the same path (checked before any run).
A run in flight stops when this machine asks (a flag file in the run's staging folder) or when its staging
folder disappears (a new campaign start removed it after a crash here), so no run is left behind.
"""

from __future__ import annotations

import dataclasses
import logging
import socket
import threading
import time
import uuid
from pathlib import Path
from typing import TYPE_CHECKING

from slamrun.backends.base import Defaults, ExecRequest, ExecResult
from slamrun.backends.machine import machine, package_versions
from slamrun.errors import InfraError, SchedulerUnreachable

if TYPE_CHECKING:
    from slamrun.backends.distributed import DistributedSpec

SILENCE_MARGIN_S = 120.0  # beyond a run's timeout, how long to wait for a worker's answer
WORKER_SILENCE_S = 20.0  # a worker without a heartbeat to the scheduler for this long is hung (stopped, frozen)
SCHEDULER_SILENCE_S = 15.0  # the client disconnected from the scheduler for this long: the scheduler is gone
PROBE_EVERY_S = 1.0  # how often the cluster's health is read (one call, shared by the lanes)


class _RemoteCancel:
    """`threading.Event`-like, read on the worker: set when the flag file exists or the run's staging
    folder is gone."""

    def __init__(self, flag: Path):
        self.flag = flag

    def is_set(self) -> bool:
        return self.flag.exists() or not self.flag.parent.exists()


def _execute_on_worker(backend_name: str, req: ExecRequest, flag: str) -> ExecResult:
    from slamrun.backends.this_machine import make_local_backend

    try:  # Dask hands a lost worker's task to another one; the campaign retries it in a fresh folder instead
        with open(Path(flag).parent / "worker.txt", "x") as fh:
            fh.write(f"{socket.gethostname()}\n")
    except FileExistsError:
        raise InfraError("its worker was lost mid-run (job ended, node gone); the run goes back to pending") from None

    def started(pid: int, t0: float) -> None:  # tells the campaign machine, through the shared folder
        tmp = Path(flag).parent / "process.txt.tmp"
        tmp.write_text(f"{socket.gethostname()} {pid} {t0!r}\n")  # pid 0: a container
        tmp.replace(tmp.with_suffix(""))

    backend = make_local_backend(backend_name)
    try:
        result = backend.execute(req, _RemoteCancel(Path(flag)), started)  # type: ignore[arg-type]
        packages = package_versions(req.modules) if backend_name == "local" and req.modules else None
        return dataclasses.replace(result, machine=machine(), packages=packages)  # this worker's, not the campaign's
    finally:
        backend.close()  # podman's API service ends with the run


def _dask_logs_to(path: Path) -> None:
    """distributed logs its reconnection attempts, with tracebacks, to the terminal; they go to a file in the
    results folder instead (the campaign says what happened in one message)."""
    names = [n for n in list(logging.Logger.manager.loggerDict) if n.startswith("distributed.")]
    for name in names:  # distributed gives some of its loggers a terminal handler of their own
        child = logging.getLogger(name)
        for handler in list(child.handlers):
            if not isinstance(handler, logging.FileHandler):
                child.removeHandler(handler)
        child.propagate = True
    logger = logging.getLogger("distributed")
    for handler in list(logger.handlers):
        if not isinstance(handler, logging.FileHandler):
            logger.removeHandler(handler)
    if not any(isinstance(h, logging.FileHandler) and h.baseFilename == str(path) for h in logger.handlers):
        path.parent.mkdir(parents=True, exist_ok=True)
        handler = logging.FileHandler(path)
        handler.setLevel(logging.WARNING)
        handler.setFormatter(logging.Formatter("%(asctime)s %(name)s %(levelname)s %(message)s"))
        logger.addHandler(handler)
    logger.propagate = False


def _kill_local_leftovers(token: str) -> None:
    """The processes of a run whose worker stopped answering, where that worker is this machine (a worker
    elsewhere stops them itself when it wakes up: the run's staging folder is gone)."""
    from slamrun.backends.local import kill_processes, processes_with_token

    if token:
        kill_processes(processes_with_token(token))


def _check_on_worker(backend_name: str, images: dict | None, probe: str) -> str | None:
    """What is wrong on this worker, or None."""
    host = socket.gethostname()
    if not Path(probe).exists():
        return f"{host}: cannot see {probe}; the results directory must be on a filesystem shared with the workers"
    try:
        from slamrun.backends.this_machine import make_local_backend

        backend = make_local_backend(backend_name)
        try:
            backend.check(images)
        finally:
            backend.close()
    except Exception as exc:  # noqa: BLE001 - reported with the worker's name
        return f"{host}: {exc}"
    return None


class DaskBackend(Defaults):
    """Runs through a Dask cluster; `name` is the backend each worker uses (local or docker)."""

    name: str  # the backend the workers run runs with (local or docker)
    engine = "dask"

    def __init__(
        self,
        backend_name: str,
        address: str | None,
        results: Path,
        local_workers: int = 2,
        connect_timeout_s: float = 30,
        jobs: DistributedSpec | None = None,
    ):
        try:
            from distributed import Client, LocalCluster
        except ImportError:
            raise InfraError("the dask engine needs the 'distributed' package: pip install distributed") from None
        self.name = backend_name
        self.address = address
        self.results = Path(results)
        _dask_logs_to(self.results / "dask.log")
        self._cluster = None
        self.excluded: set[str] = set()  # workers that stopped answering: no more runs go to them
        self._health_lock = threading.Lock()
        self._probed_at = 0.0
        self._beats: dict[str, tuple[float, float]] = {}  # worker -> (its last_seen, when it changed here)
        self._processing: dict[str, str] = {}  # task key -> worker running it
        self._disconnected_since: float | None = None
        self._jobs = jobs
        if jobs is not None:  # workers as batch jobs this campaign submits and cancels
            from slamrun.backends.jobqueue import start_job_cluster

            self._cluster, self.client = start_job_cluster(jobs, self.results, local_workers)
            self.address = f"{jobs.cluster} ({self._cluster.scheduler_address})"
            return
        try:
            if address == "local":
                self._cluster = LocalCluster(
                    n_workers=local_workers,
                    threads_per_worker=1,
                    processes=True,
                    host="127.0.0.1",
                    dashboard_address="127.0.0.1:0",
                )
                self.client = Client(self._cluster)
            else:
                self.client = Client(address, timeout=connect_timeout_s)
        except OSError as exc:
            raise InfraError(f"cannot reach the Dask scheduler at {address}: {exc}") from None

    def check(self, images: dict[str, str | None] | None = None) -> None:
        """Every worker sees the results directory and can run the methods (its daemon, its images)."""
        probe = self.results / f".slamrun-probe-{uuid.uuid4().hex}"
        probe.write_text("slamrun: shared filesystem probe\n")
        try:
            problems = self.client.run(_check_on_worker, self.name, images, str(probe))
        finally:
            probe.unlink(missing_ok=True)
        if not problems:
            raise InfraError("the Dask cluster has no workers; start some (dask worker ADDRESS)")
        bad = [p for p in problems.values() if p]
        if bad:
            raise InfraError("Dask workers cannot run the campaign:\n  " + "\n  ".join(bad))

    def process_paths(self, view, workdir):
        from slamrun.backends.this_machine import make_local_backend

        return make_local_backend(self.name).process_paths(view, workdir)

    def execute(self, req: ExecRequest, cancel: threading.Event, on_start=None) -> ExecResult:
        """Submit the run to a worker and wait. A cancel here drops a run still queued on the cluster and
        raises the flag that makes the worker stop one already started. The worker enforces the run's
        timeout; a worker silent well past it is an infrastructure fault.

        CPU pinning is the worker's business (its own cores), so the lane's CPU set is not sent."""
        flag = req.workdir.parent / "cancel.flag"
        process_txt = req.workdir.parent / "process.txt"
        remote = dataclasses.replace(req, cpus=None)
        live = self._live_workers() if self.excluded else []
        if self.excluded and not live:
            raise InfraError(f"no Dask worker answers (stopped answering: {', '.join(sorted(self.excluded))})")
        future = self.client.submit(
            _execute_on_worker,
            self.name,
            remote,
            str(flag),
            pure=False,
            key=f"slamrun-{uuid.uuid4().hex}",
            workers=live if self.excluded else None,  # never to a worker that stopped answering
            allow_other_workers=False,
        )
        raised = False
        started_at = None
        try:
            while not future.done():
                hung = self._hung_worker_of(future.key)
                if hung:
                    flag.touch()  # a worker that wakes up stops the run
                    future.cancel()
                    _kill_local_leftovers(req.token)
                    raise InfraError(
                        f"the Dask worker {hung} stopped answering (no heartbeat for {WORKER_SILENCE_S:.0f} s); "
                        "it gets no more runs of this campaign"
                    )
                if cancel.is_set() and not raised:
                    flag.touch()
                    raised = True
                    if started_at is None:
                        future.cancel()
                        return ExecResult(exit_code=None, wall_s=0.0, cancelled=True)
                if started_at is None and process_txt.exists():
                    started_at = time.monotonic()
                    host, pid, t0 = process_txt.read_text().split()
                    if on_start and int(pid) and host == socket.gethostname():  # crash recovery can kill it
                        on_start(int(pid), float(t0))
                if started_at is not None and time.monotonic() - started_at > req.timeout_s + SILENCE_MARGIN_S:
                    raise InfraError(f"the Dask worker running it has not answered for {req.timeout_s:.0f} s + margin")
                time.sleep(0.05)
            return future.result()
        except (InfraError, OSError):
            raise
        except Exception as exc:  # noqa: BLE001 - a worker died, the scheduler went away, ...
            if self.client.status != "running":
                raise self._scheduler_lost() from None
            raise InfraError(f"the Dask worker could not run it: {type(exc).__name__}: {exc}") from None
        finally:
            process_txt.unlink(missing_ok=True)
            if raised:
                flag.unlink(missing_ok=True)

    def _scheduler_lost(self) -> SchedulerUnreachable:
        return SchedulerUnreachable(
            f"the Dask scheduler at {self.address} stopped answering; no new run was started. Restart it (and its "
            "workers) and run the same command: finished runs are kept, the others run then"
        )

    def _probe(self) -> None:
        """Read the cluster's health (at most every PROBE_EVERY_S, one call for every lane): which worker
        processes which task, and since when each worker's heartbeat has not changed. A scheduler the client
        has been disconnected from for SCHEDULER_SILENCE_S is lost."""
        now = time.monotonic()
        if now - self._probed_at < PROBE_EVERY_S:
            return
        self._probed_at = now
        if self.client.status != "running":
            self._disconnected_since = self._disconnected_since or now
            if now - self._disconnected_since > SCHEDULER_SILENCE_S:
                raise self._scheduler_lost()
            return
        try:
            workers = self.client.scheduler_info(n_workers=-1)["workers"]
            processing = self.client.processing()
        except Exception:  # noqa: BLE001 - the scheduler is going away: judged by the client's status
            self._disconnected_since = self._disconnected_since or now
            if now - self._disconnected_since > SCHEDULER_SILENCE_S:
                raise self._scheduler_lost() from None
            return
        self._disconnected_since = None
        for address, info in workers.items():
            seen = float(info.get("last_seen") or 0.0)
            before = self._beats.get(address)
            if before is None or before[0] != seen:
                self._beats[address] = (seen, now)
        self._processing = {str(key): address for address, keys in processing.items() for key in keys}

    def _hung_worker_of(self, key: str) -> str | None:
        """The worker a task is on when that worker stopped answering (it is excluded from then on)."""
        with self._health_lock:
            self._probe()
            address = self._processing.get(str(key))
            if address is None:
                return None
            beat = self._beats.get(address)
            if address in self.excluded or (beat and time.monotonic() - beat[1] > WORKER_SILENCE_S):
                self.excluded.add(address)
                return address
            return None

    def _live_workers(self) -> list[str]:
        with self._health_lock:
            self._probed_at = 0.0
            self._probe()
            return [w for w in self._beats if w not in self.excluded]

    def close(self) -> None:
        try:
            self.client.close(timeout=10)
        except Exception:  # noqa: BLE001 - a scheduler that is gone cannot be said goodbye to
            pass
        if self._cluster is not None:
            self._cluster.close()
        if self._jobs is not None:  # the cluster cancels its jobs; what it lost track of goes too
            from slamrun.backends.jobqueue import cancel_jobs, job_name

            cancel_jobs(self._jobs.cluster, job_name(self.results))
