"""Distributed engine: each run's process is started by a Dask worker (on another machine, or on this one).

The scheduler, the ledger and every file decision stay on this machine; a worker only runs the method's
process with the local or Docker backend and writes its log and resources.csv. So the results directory
and the view cache must be on a filesystem all workers see at the same path (checked before any run).
A run in flight stops when this machine asks (a flag file in the run's staging folder) or when its staging
folder disappears (a new campaign start removed it after a crash here), so no run is left behind.
"""

from __future__ import annotations

import dataclasses
import socket
import threading
import time
import uuid
from pathlib import Path

from runner.backends.base import Defaults, ExecRequest, ExecResult
from runner.errors import InfraError

SILENCE_MARGIN_S = 120.0  # beyond a run's timeout, how long to wait for a worker's answer


class _RemoteCancel:
    """`threading.Event`-like, read on the worker: set when the flag file exists or the run's staging
    folder is gone."""

    def __init__(self, flag: Path):
        self.flag = flag

    def is_set(self) -> bool:
        return self.flag.exists() or not self.flag.parent.exists()


def _execute_on_worker(backend_name: str, req: ExecRequest, flag: str) -> ExecResult:
    from runner.backends import make_local_backend

    def started(pid: int, t0: float) -> None:  # tells the campaign machine, through the shared folder
        tmp = Path(flag).parent / "process.txt.tmp"
        tmp.write_text(f"{socket.gethostname()} {pid} {t0!r}\n")  # pid 0: a container
        tmp.replace(tmp.with_suffix(""))

    return make_local_backend(backend_name).execute(req, _RemoteCancel(Path(flag)), started)  # type: ignore[arg-type]


def _check_on_worker(backend_name: str, images: dict | None, probe: str) -> str | None:
    """What is wrong on this worker, or None."""
    host = socket.gethostname()
    if not Path(probe).exists():
        return f"{host}: cannot see {probe}; the results directory must be on a filesystem shared with the workers"
    try:
        from runner.backends import make_local_backend

        make_local_backend(backend_name).check(images)
    except Exception as exc:  # noqa: BLE001 - reported with the worker's name
        return f"{host}: {exc}"
    return None


class DaskBackend(Defaults):
    """Runs through a Dask cluster; `name` is the backend each worker uses (local or docker)."""

    name: str  # the backend the workers run runs with (local or docker)
    engine = "dask"

    def __init__(
        self, backend_name: str, address: str, results: Path, local_workers: int = 2, connect_timeout_s: float = 30
    ):
        try:
            from distributed import Client, LocalCluster
        except ImportError:
            raise InfraError("the dask engine needs the 'distributed' package: pip install distributed") from None
        self.name = backend_name
        self.results = Path(results)
        self._cluster = None
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
        from runner.backends import make_local_backend

        return make_local_backend(self.name).process_paths(view, workdir)

    def execute(self, req: ExecRequest, cancel: threading.Event, on_start=None) -> ExecResult:
        """Submit the run to a worker and wait. A cancel here drops a run still queued on the cluster and
        raises the flag that makes the worker stop one already started. The worker enforces the run's
        timeout; a worker silent well past it is an infrastructure fault.

        CPU pinning is the worker's business (its own cores), so the lane's CPU set is not sent."""
        flag = req.workdir.parent / "cancel.flag"
        process_txt = req.workdir.parent / "process.txt"
        remote = dataclasses.replace(req, cpus=None)
        future = self.client.submit(
            _execute_on_worker, self.name, remote, str(flag), pure=False, key=f"slamrun-{uuid.uuid4().hex}"
        )
        raised = False
        started_at = None
        try:
            while not future.done():
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
            raise InfraError(f"the Dask worker could not run it: {type(exc).__name__}: {exc}") from None
        finally:
            process_txt.unlink(missing_ok=True)
            if raised:
                flag.unlink(missing_ok=True)

    def close(self) -> None:
        self.client.close()
        if self._cluster is not None:
            self._cluster.close()
