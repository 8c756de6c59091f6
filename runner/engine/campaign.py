"""A campaign from spec to results: datasets, lock, ledger, recovery, plan, preparation, runs, export."""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import yaml

import methods
from runner.backends import make_backend
from runner.backends.base import Backend
from runner.datasets.cache import prepare, remove_damaged
from runner.datasets.tum_mono import open_sequence
from runner.engine.ledger import Ledger, ResultsLock
from runner.engine.plan import PlannedRun, plan
from runner.engine.preparer import ViewPreparer
from runner.engine.recovery import collect_leftovers, import_finished, recover
from runner.engine.scheduler import Event, Scheduler
from runner.engine.spec import CampaignSpec
from runner.errors import DaemonUnreachable, DatasetError, DiskFullError, LedgerLostError, is_disk_full
from runner.results.vocabulary import is_infra


@dataclass
class CampaignResult:
    results: Path
    results_csv: Path
    counts: dict[str, int]
    recovered: dict[str, int]
    added: int
    infra_failures: int
    interrupted: bool


def ensure_datasets(spec: CampaignSpec, log=print) -> None:
    """Generate the synthetic sequences a spec asks for and that are not on disk yet."""
    from runner.datasets import synth  # scipy: imported only when a sequence is generated

    for ds in spec.datasets:
        if ds.synthetic is None:
            continue
        for i, seq in enumerate(ds.sequences):
            folder = ds.path / seq
            if (folder / "times.txt").exists():
                continue
            log(f"generating synthetic sequence {folder} ({ds.synthetic.frames} frames)")
            synth.generate(
                folder,
                frames=ds.synthetic.frames,
                seed=ds.synthetic.seed + i,
                size=ds.synthetic.size_wh,
                scene_kind=ds.synthetic.scene.value,
            )


def prepare_views(spec: CampaignSpec, runs: list[PlannedRun], keys: set[str], log=print) -> dict:
    """The views the runs `keys` need, prepared (and checked) now; damaged ones left from earlier go first."""
    removed = remove_damaged(spec.cache)
    if removed:
        log(f"removed {removed} damaged view(s) from {spec.cache}")
    views = {}
    for r in runs:
        k = (str(r.sequence_dir), r.key.direction, r.profile)
        if r.key.id in keys and k not in views:
            views[k] = prepare(r.sequence_dir, r.key.direction, r.profile, spec.cache, frame_format=spec.frame_format)
    return views


def session_record(spec: CampaignSpec) -> dict:
    """Who runs the campaign now, since when, on how many lanes (for status, --watch and the ETA)."""
    import psutil

    me = psutil.Process()
    lanes = 1 if spec.measurement == "exclusive" else spec.lanes
    return {"pid": me.pid, "pid_start": me.create_time(), "started_at": time.time(), "lanes": lanes, "ended_at": None}


def session_alive(session: dict | None) -> bool:
    """Whether the campaign process of a session record still runs (same PID and start time)."""
    import psutil

    if not session or session.get("ended_at"):
        return False
    try:
        return abs(psutil.Process(session["pid"]).create_time() - session["pid_start"]) < 0.01
    except (psutil.Error, KeyError, TypeError):
        return False


def check_sequences(spec: CampaignSpec, skip_ungenerated: bool = False) -> list[str]:
    """Open every sequence of the spec as a run would; one DatasetError lists every problem. Returns the
    warnings (a sequence that cannot be evaluated although the spec asks for evaluation). With
    `skip_ungenerated`, synthetic sequences not generated yet are left out."""
    problems, warnings = [], []
    for ds in spec.datasets:
        for seq in ds.sequences:
            folder = ds.path / seq
            if skip_ungenerated and ds.synthetic is not None and not (folder / "times.txt").exists():
                continue
            try:
                sequence = open_sequence(folder)
                if spec.evaluate:
                    if sequence.groundtruth_path is None:
                        warnings.append(
                            f"{folder}: no groundtruthSync.txt: its runs cannot be evaluated (they are kept, "
                            "without metrics); add the file or set evaluate: false"
                        )
                    else:
                        sequence.groundtruth()
            except DatasetError as exc:
                problems.append(str(exc))
    if problems:
        raise DatasetError(f"{len(problems)} sequence(s) cannot be used:\n" + "\n".join(problems))
    return warnings


def load_groundtruths(runs: list[PlannedRun]) -> dict:
    """groundtruthSync.txt of every sequence in the plan (None where a sequence has none)."""
    gts = {}
    for r in runs:
        if str(r.sequence_dir) not in gts:
            gts[str(r.sequence_dir)] = open_sequence(r.sequence_dir).groundtruth()
    return gts


def run_campaign(
    spec: CampaignSpec, backend: Backend | None = None, on_event: Event | None = None, scheduler_hook=None, log=print
) -> CampaignResult:
    """Plan, recover, prepare, run and export. A full disk at any step stops it with DiskFullError, whose
    message says what to do; finished runs and the ledger are never damaged by it."""
    try:
        return _run_campaign(spec, backend, on_event, scheduler_hook, log)
    except DiskFullError:
        raise
    except Exception as exc:
        if is_disk_full(exc):
            raise DiskFullError(f"{exc}\n{_full_disk_advice(spec)}") from exc
        raise


def _full_disk_advice(spec: CampaignSpec) -> str:
    return (
        f"Stopped: a disk is full (results {spec.results}, view cache {spec.cache}). Finished runs and the ledger "
        "are intact; free some space, then run `make campaign` (or `slamrun campaign SPEC`) again to resume."
    )


def _run_campaign(spec: CampaignSpec, backend, on_event, scheduler_hook, log) -> CampaignResult:
    results = spec.results
    assert results is not None
    ensure_datasets(spec, log)
    for warning in check_sequences(spec):
        log(f"warning: {warning}")
    lock = ResultsLock(results)
    lock.acquire()
    try:
        ledger = Ledger(results / "ledger.sqlite")
        ledger.set_meta("campaign", spec.name)
        ledger.set_meta("spec", spec.model_dump(mode="json"))
        (results / "spec.resolved.yaml").write_text(yaml.safe_dump(json.loads(spec.model_dump_json()), sort_keys=False))
        docker_here = spec.backend == "docker" and spec.distributed is None
        recovered = recover(ledger, results, keep_attempts=docker_here)
        runs = plan(spec)
        added = ledger.sync_plan(runs)
        recovered["imported"] += import_finished(ledger, runs, results)
        backend = backend or make_backend(spec)
        images = {m.run_label: methods.get(m.name)(m.params).image for m in spec.methods}
        backend.check(images)
        described = {label: backend.describe_image(tag) for label, tag in images.items() if tag}
        if any(d is not None for d in described.values()):  # which image, from which sources, made these results
            (results / "images.json").write_text(json.dumps(described, indent=1))
        pending = set(ledger.pending_keys())
        removed = remove_damaged(spec.cache)
        if removed:
            log(f"removed {removed} damaged view(s) from {spec.cache}")
        # views are prepared in the background, in the order the runs start; a lane waits only for its own
        order = [(str(r.sequence_dir), r.key.direction, r.profile) for r in runs if r.key.id in pending]
        lanes = 1 if spec.measurement == "exclusive" else spec.lanes
        views = ViewPreparer(order, spec.cache, spec.frame_format, head=lanes).start()  # the idle lanes' first views
        gts = load_groundtruths(runs) if spec.evaluate else {}
        sched = Scheduler(spec, ledger, backend, views, gts, on_event)
        # containers left by a killed runner or a lost daemon
        n = collect_leftovers(
            backend, spec.name, ledger, runs, sched.methods, views.get, gts, results, int(spec.log_cap_mb * 2**20)
        )
        if n:
            log(f"collected {n} run(s) whose container finished while the runner or the daemon was away")
        recovered["collected"] = n
        if scheduler_hook:
            scheduler_hook(sched)
        ledger.set_meta("eta", {"pending": len(pending), "lanes": spec.lanes})
        session = session_record(spec)
        ledger.set_meta("session", session)
        try:
            sched.run(runs)
        finally:
            views.close()
            backend.close()
            try:
                ledger.set_meta(
                    "session",
                    {**session, "ended_at": time.time(), "runs_from": sched.started_at, "runs_to": sched.ended_at},
                )
            except Exception:  # noqa: BLE001 - a lost ledger or a full disk: status then sees the process gone
                pass
        remove_damaged(spec.cache)  # no run in flight any more
        from runner.engine.export import export  # pandas: imported after the runs, not before the first one starts

        if isinstance(sched.fatal_error, LedgerLostError):
            ledger.close()
            raise sched.fatal_error
        if isinstance(sched.fatal_error, DaemonUnreachable):
            export(ledger, results)
            ledger.close()
            raise sched.fatal_error
        try:
            csv = export(ledger, results)
        except Exception as exc:
            if not (sched.fatal or is_disk_full(exc)):
                raise
            sched.fatal = sched.fatal or f"{results}: the disk is full ({exc})"
        if sched.fatal:
            ledger.close()
            raise DiskFullError(f"{sched.fatal}\n{_full_disk_advice(spec)}")
        counts = ledger.counts()
        infra = sum(1 for r in ledger.rows(state="failed") if is_infra(r["state"], r["failure"]))
        ledger.close()
        return CampaignResult(results, csv, counts, recovered, added, infra, sched.stop.is_set())
    finally:
        lock.release()
