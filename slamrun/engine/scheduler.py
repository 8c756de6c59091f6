"""The scheduler: lanes pull pending runs, each lane pinned to its own CPU set.

Method failures are recorded as data and never retried; infrastructure failures are retried with a
doubling backoff up to the configured count. `stop` stops new runs from starting; `cancel` stops the
runs in flight (they go back to pending).
"""

from __future__ import annotations

import os
import sys
import threading
import time
import traceback
from collections import deque
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

from slamrun.backends.base import Backend
from slamrun.core.trajectory import Trajectory
from slamrun.datasets.view import PreparedView
from slamrun.engine.execute import Launched, RunOutcome, finish_attempt, launch_run
from slamrun.engine.ledger import Ledger
from slamrun.engine.paths import RunPaths, finished_record
from slamrun.engine.plan import PlannedRun
from slamrun.engine.preparer import ViewPreparer
from slamrun.engine.spec import CampaignSpec
from slamrun.errors import (
    BackendUnreachable,
    Contended,
    DatasetError,
    InfraError,
    LedgerLostError,
    SlamRunError,
    StorageError,
    storage_problem,
)
from slamrun.methods import get as get_method
from slamrun.methods.base import Method
from slamrun.results.vocabulary import CONTENDED, INFRA


@dataclass(frozen=True)
class Lane:
    index: int
    cpus: tuple[int, ...] | None


def make_lanes(n: int, cpus_per_lane: int | None = None, exclusive: bool = False) -> list[Lane]:
    """Split the CPUs this process may use into `n` lanes (exclusive mode: one lane, every CPU)."""
    available = sorted(os.sched_getaffinity(0))
    if exclusive:
        return [Lane(0, tuple(available))]
    per = min(len(available), cpus_per_lane or max(1, len(available) // n))  # a lane never lists a CPU twice
    return [Lane(i, tuple(available[(i * per + j) % len(available)] for j in range(per))) for i in range(n)]


Event = Callable[[str, PlannedRun, Lane, dict], None]  # (started|finished|retry|requeued, run, lane, info)


class Scheduler:
    def __init__(
        self,
        spec: CampaignSpec,
        ledger: Ledger,
        backend: Backend,
        views: ViewPreparer,
        groundtruths: dict[str, Trajectory | None],
        on_event: Event | None = None,
    ):
        self.spec = spec
        self.ledger = ledger
        self.backend = backend
        self.views = views
        self.groundtruths = groundtruths
        self._observer = on_event or (lambda *a: None)
        self.stop = threading.Event()  # no new runs
        self.cancel = threading.Event()  # stop runs in flight
        self._queue: deque[PlannedRun] = deque()
        self._qcond = threading.Condition()
        self._finishing = 0  # runs handed to the finishing threads and not recorded yet
        self._finisher: ThreadPoolExecutor | None = None
        self.started_at = self.ended_at = None
        self.fatal_error: SlamRunError | None = None  # the error that stopped it (full disk, ledger lost)
        self.methods = {i: get_method(m.name)(m.params).for_backend(backend.name) for i, m in enumerate(spec.methods)}
        self.results_id = str(ledger.meta("results_id") or "")  # on each container, beside the campaign's name
        self._seeded: dict[tuple[int, int], Method] = {}

    def method_of(self, run: PlannedRun) -> Method:
        """The method as the run takes it: with its trial's seed where the plan derived one (engine.plan.trial_seed)."""
        if run.seed is None:
            return self.methods[run.method_index]
        key = (run.method_index, run.seed)
        if key not in self._seeded:
            m = self.spec.methods[run.method_index]
            cls = get_method(m.name)
            self._seeded[key] = cls({**m.params, cls.seed_param: run.seed}).for_backend(self.backend.name)
        return self._seeded[key]

    def on_event(self, kind: str, run: PlannedRun, lane: Lane, info: dict) -> None:
        """Tell the observer (the live display, a caller's hook). What it raises is printed and never changes a
        run's record: a run recorded done stays done."""
        try:
            self._observer(kind, run, lane, info)
        except Exception:  # noqa: BLE001 - an observer's bug is not the run's
            print(f"slamrun: an event observer failed on '{kind}' of {run.key.id} (the run's record stands):",
                  file=sys.stderr)  # fmt: skip
            traceback.print_exc(file=sys.stderr)

    def run(self, runs: list[PlannedRun]) -> None:
        pending = set(self.ledger.pending_keys())
        self._queue = deque(r for r in runs if r.key.id in pending)
        exclusive = self.spec.measurement == "exclusive"
        lanes = make_lanes(1 if exclusive else self.spec.lanes, self.spec.cpus_per_lane, exclusive)
        threads = [
            threading.Thread(target=self._lane_loop, args=(lane,), name=f"lane-{lane.index}", daemon=True)
            for lane in lanes
        ]
        self._finisher = None if exclusive else ThreadPoolExecutor(max_workers=len(lanes), thread_name_prefix="finish")
        self.started_at = time.time()
        for t in threads:
            t.start()
        stop_seen_at = None
        while any(t.is_alive() for t in threads):
            for t in threads:
                t.join(timeout=0.1)
            if self.stop.is_set() and stop_seen_at is None:
                stop_seen_at = time.monotonic()
            if stop_seen_at is not None and time.monotonic() - stop_seen_at > self.spec.stop_grace_s:
                self.cancel.set()
        if self._finisher is not None:
            self._finisher.shutdown(wait=True)  # the runs whose process ended are recorded before the end
        self.ended_at = time.time()

    def request_stop(self, now: bool = False) -> None:
        self.stop.set()
        if now:
            self.cancel.set()

    def _next(self) -> PlannedRun | None:
        """The next run; None when there is none left, no finishing run may send one back, or on stop."""
        with self._qcond:
            while not self.stop.is_set():
                if self._queue:
                    return self._queue.popleft()
                if self._finishing == 0:
                    return None
                self._qcond.wait(0.2)
            return None

    def _lane_loop(self, lane: Lane) -> None:
        while (run := self._next()) is not None:
            try:
                self._run_with_retries(run, lane)
            except StorageError as exc:  # the run did not finish: it goes back to pending
                self._stop_for_storage(run, lane, exc, requeue=True)
            except LedgerLostError as exc:  # nothing can be recorded any more: stop starting runs
                self.fatal_error = self.fatal_error or exc
                self.request_stop()
                self.on_event("requeued", run, lane, {"message": str(exc)})
            except Exception as exc:
                if why := storage_problem(exc):  # the ledger could not be written: the next start recovers the row
                    self._stop_for_storage(run, lane, StorageError(f"{run.key.id}: {why} ({exc})", why), requeue=False)
                    continue
                # a bug: keep the traceback, record it, let the other runs go on
                self._record_infra(run, lane, traceback.format_exc())

    def _record_infra(self, run: PlannedRun, lane: Lane, message: str, failure: str = INFRA) -> None:
        """The run failed for infrastructure reasons (not the method's result; `contended`: the machine's load):
        recorded, retried next start."""
        self.ledger.finish(run.key.id, "failed", {"failure": failure, "message": message[-2000:]})
        self.on_event("finished", run, lane, {"status": "failed", "failure": failure, "message": message})

    def _stop_for_storage(self, run: PlannedRun, lane: Lane, error: StorageError, requeue: bool) -> None:
        """No new runs. A row the ledger cannot update stays `running`: the next start recovers it (imports
        the run if its folder is complete, else requeues it)."""
        self.fatal_error = self.fatal_error or error
        self.request_stop()
        if requeue:
            try:
                self.ledger.reset_to_pending(run.key.id)
            except Exception as exc:  # noqa: BLE001 - only a storage failure is expected here
                if not storage_problem(exc):
                    raise
        self.on_event("requeued", run, lane, {"message": str(error)})

    def _checked_view(self, run: PlannedRun, lane: Lane) -> PreparedView:
        """The run's prepared view, whole: one found missing or damaged (deleted cache, a method that wrote
        into it) is prepared again first, so no run is charged for it. A view that cannot be prepared is an
        infrastructure failure (a full disk stops the campaign)."""
        try:
            view, problem = self.views.checked(run.view_key)
        except DatasetError as exc:
            raise InfraError(f"{run.key.id}: its view cannot be prepared: {exc}") from None
        except OSError as exc:
            if why := storage_problem(exc):
                raise StorageError(f"{run.key.id}: {why} while preparing its view ({exc})", why) from None
            raise InfraError(f"{run.key.id}: its view cannot be prepared: {exc}") from None
        if problem is not None:
            self.on_event("view", run, lane, {"message": f"{problem}; prepared again"})
        return view

    def _run_with_retries(self, run: PlannedRun, lane: Lane) -> None:
        method = self.method_of(run)
        paths = RunPaths(self.spec.results, run.key)
        rec = finished_record(paths.final, run.key.id)
        if rec is not None:  # finished earlier and not in the ledger (it was lost): record it, never redo it
            self.ledger.finish(run.key.id, rec["status"], {**rec, "run_dir": str(paths.final)})
            self.on_event("finished", run, lane, {**rec, "imported": True})
            return
        for retry in range(self.spec.retries + 1):
            attempt = self.ledger.mark_running(run.key.id, str(paths.final))
            self.on_event("started", run, lane, {"attempt": attempt})
            try:
                view = self._checked_view(run, lane)
                launched = launch_run(
                    run,
                    method,
                    view,
                    self.backend,
                    paths,
                    attempt,
                    self.cancel,
                    cpus=lane.cpus,
                    memory_mb=self.spec.memory_limit_mb,
                    log_cap_bytes=int(self.spec.log_cap_mb * 2**20),
                    max_output_bytes=int(self.spec.max_output_mb * 2**20),
                    campaign=self.spec.name,
                    results_id=self.results_id,
                    on_start=lambda pid, t0: self.ledger.set_process(run.key.id, pid, t0),
                )
            except StorageError:
                raise
            except BackendUnreachable as exc:  # no run can start: stop; the next start collects or redoes it
                self.fatal_error = self.fatal_error or exc
                self.request_stop()
                self.ledger.reset_to_pending(run.key.id)
                self.on_event("requeued", run, lane, {"message": str(exc)})
                return
            except InfraError as exc:
                if retry < self.spec.retries and not self.stop.is_set():
                    delay = self.spec.retry_backoff_s * 2**retry
                    self.ledger.reset_to_pending(run.key.id)
                    self.on_event("retry", run, lane, {"message": str(exc), "delay_s": delay})
                    if self.stop.wait(delay):
                        return
                    continue
                self._record_infra(run, lane, str(exc))
                return
            if isinstance(launched, RunOutcome):  # cancelled
                self.ledger.reset_to_pending(run.key.id)
                self.on_event("requeued", run, lane, {})
                return
            job = (run, lane, method, view, paths, attempt, launched)
            with self._qcond:
                self._finishing += 1
            if self._finisher is None:  # exclusive timing: nothing else may run beside the next run
                self._finish(*job)
            else:  # off the lane: the next run starts now
                self._finisher.submit(self._finish, *job)
            return

    def _finish(self, run, lane, method, view, paths, attempt, launched: Launched) -> None:
        try:
            self._record(run, lane, method, view, paths, attempt, launched)
        finally:
            with self._qcond:
                self._finishing -= 1
                self._qcond.notify_all()

    def _record(self, run, lane, method, view, paths, attempt, launched: Launched) -> None:
        """Read, evaluate, record and rename a run whose process ended. An infrastructure fault found now
        (the view vanished or was damaged under the run) sends the run back to the queue, up to `retries`."""
        gt = self.groundtruths.get(str(run.sequence_dir)) if self.spec.evaluate else None
        try:
            outcome = finish_attempt(
                run,
                method,
                view,
                paths,
                attempt,
                launched.result,
                launched.started,
                gt,
                launched.extra,
                self.spec.contention_pct,
            )
            self.ledger.finish(run.key.id, outcome.state, outcome.values)
            self.on_event("finished", run, lane, {"status": outcome.state, **outcome.values})
        except StorageError as exc:
            self._stop_for_storage(run, lane, exc, requeue=True)
        except LedgerLostError as exc:
            self.fatal_error = self.fatal_error or exc
            self.request_stop()
        except InfraError as exc:
            if isinstance(exc, Contended):
                self.ledger.note_contended(run.key.id, str(exc))
            if attempt <= self.spec.retries and not self.stop.is_set():
                self.ledger.reset_to_pending(run.key.id)
                self.on_event("retry", run, lane, {"message": str(exc), "delay_s": 0.0})
                with self._qcond:
                    self._queue.appendleft(run)
                    self._qcond.notify_all()
                return
            self._record_infra(run, lane, str(exc), CONTENDED if isinstance(exc, Contended) else INFRA)
        except Exception as exc:
            if why := storage_problem(exc):
                self._stop_for_storage(run, lane, StorageError(f"{run.key.id}: {why} ({exc})", why), requeue=False)
                return
            self._record_infra(run, lane, traceback.format_exc())
