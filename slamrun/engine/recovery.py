"""Recovery at the start of a campaign: what a crash, a lost ledger or a lost Docker daemon left behind.

Nothing that finished is redone: runs whose folder is complete are imported, containers that completed
while their runner or the daemon was away are collected; stale rows go back to pending and their
processes are stopped.
"""

from __future__ import annotations

import shutil
from pathlib import Path

from slamrun.core.trajectory import Trajectory
from slamrun.datasets.view import PreparedView
from slamrun.engine.execute import finish_attempt
from slamrun.engine.ledger import Ledger
from slamrun.engine.paths import RunPaths, finished_record, run_token
from slamrun.engine.plan import PlannedRun
from slamrun.errors import SlamRunError
from slamrun.methods.base import Method


def import_finished(ledger: Ledger, runs: list[PlannedRun], results: Path) -> int:
    """Pending runs whose folder already holds a finished run (a lost or reset ledger) are recorded from
    their run.json instead of being run again; returns how many."""
    pending = set(ledger.pending_keys())
    n = 0
    for run in runs:
        if run.key.id not in pending:
            continue
        final = RunPaths(results, run.key).final
        rec = finished_record(final, run.key.id)
        if rec is not None:
            ledger.finish(run.key.id, rec["status"], {**rec, "run_dir": str(final)})
            n += 1
    return n


def recover(ledger: Ledger, results: Path, keep_attempts: bool = False) -> dict[str, int]:
    """After a crash: finished-but-unrecorded runs are imported, stale `running` rows go back to pending.
    With `keep_attempts` their half-written attempt folders stay, for `collect_leftovers` (Docker)."""
    from slamrun.backends.local import kill_processes, kill_stale, processes_with_token

    imported = requeued = killed = 0
    for row in ledger.stale_running():
        if row["pid"]:
            killed += kill_stale(row["pid"], row["pid_start"])
        if row["run_dir"] and row["attempts"]:  # its processes that left the group, by their token
            token = run_token(Path(row["run_dir"]), row["attempts"])
            killed += kill_processes(processes_with_token(token))
        rec = finished_record(Path(row["run_dir"]), row["key"]) if row["run_dir"] else None
        if rec is not None:
            ledger.finish(row["key"], rec["status"], {**rec, "run_dir": row["run_dir"]})
            imported += 1
            continue
        ledger.reset_to_pending(row["key"])
        if row["run_dir"] and not keep_attempts:
            # its half-written attempt: removing it also stops a process left on a Dask worker
            final = Path(row["run_dir"])
            for stage in final.parent.glob(f".{final.name}.tmp-*"):
                shutil.rmtree(stage, ignore_errors=True)
        requeued += 1
    return {"imported": imported, "requeued": requeued, "killed": killed, "infra_reset": ledger.reset_infra_failures()}


def collect_leftovers(
    backend,
    owner: tuple[str, str],
    ledger: Ledger,
    runs: list[PlannedRun],
    methods_by_index: dict[int, Method],
    view_of,
    groundtruths: dict[str, Trajectory | None],
    results: Path,
    log_cap_bytes: int,
) -> int:
    """Containers this campaign left behind in this results folder (`owner`: the campaign's name and the folder's
    results_id; its runner killed, or the Docker daemon lost mid-run): one that exited by itself with a complete,
    accepted output is recorded as its run's attempt; every other one is removed and its run stays pending. The
    same campaign's containers of another results folder are left alone. `view_of(key)` gives a run's prepared
    view. Returns how many were collected."""
    by_key = {r.key.id: r for r in runs}
    collected = 0
    for container in backend.leftovers(*owner):
        labels = container.labels or {}
        run = by_key.get(labels.get("slamrun.run", ""))
        row = ledger.get(run.key.id) if run else None
        try:
            attempt = int(labels.get("slamrun.attempt", "0"))
        except ValueError:
            attempt = 0
        paths = RunPaths(results, run.key) if run else None
        if run and row and row["status"] == "pending" and attempt and paths.staging(attempt).is_dir():
            view = view_of(run.view_key)
            stage = paths.staging(attempt)
            result = backend.collect(container, RunPaths.log(stage), log_cap_bytes, view.n_frames) if view else None
            method = methods_by_index[run.method_index]
            if result is not None and _complete(method, result, RunPaths.raw(stage), view):
                started = container.attrs.get("State", {}).get("StartedAt")
                extra = {
                    "backend": backend.name,
                    "collected": f"container finished while away (started {started}); its log lacks what it printed "
                    "while the daemon was down, its resource samples were lost",
                }
                outcome = finish_attempt(
                    run, method, view, paths, attempt, result, 0.0, groundtruths.get(str(run.sequence_dir)), extra
                )
                ledger.finish(run.key.id, outcome.state, outcome.values)
                collected += 1
        container.remove(force=True)
        if paths is not None:
            paths.clear_staging()
    return collected


def _complete(method: Method, result, raw: Path, view: PreparedView) -> bool:
    """An exit the method accepts and an output it can read: only then is a collected run judged; anything
    less is redone rather than charged to the method on a partial record."""
    if not method.accepts_exit(result.exit_code, raw):
        return False
    try:
        return len(method.read_trajectory(raw, view)) > 0
    except SlamRunError:
        return False
