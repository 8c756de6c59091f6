"""One run, start to finish: configure, execute, read, evaluate, write, rename.

A run's folder appears (by rename) only when all its files are written, so a half-finished run never
looks complete. Method failures come back as data; infrastructure faults raise InfraError.
"""

from __future__ import annotations

import os
import shutil
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import slamrun.methods
from slamrun.backends.base import Backend, ExecRequest, ExecResult, disk_reserve_bytes, folder_bytes
from slamrun.backends.logcap import tail
from slamrun.backends.machine import machine, package_versions, packages_text, source_commit
from slamrun.core import jsonio
from slamrun.core.evaluation import ASSOCIATION_TOLERANCE_S
from slamrun.core.nearest import nearest
from slamrun.core.trajectory import Trajectory, write_tum
from slamrun.datasets.cache import verify_view
from slamrun.datasets.view import PreparedView
from slamrun.engine.paths import RunPaths, finished_record
from slamrun.engine.plan import PlannedRun
from slamrun.engine.run_evaluation import Frames, evaluate_trajectory, run_frames, settle
from slamrun.errors import (
    BackendUnreachable,
    Contended,
    InfraError,
    MethodFailure,
    StorageError,
    TrajectoryFormatError,
    storage_problem,
)
from slamrun.methods.base import Method
from slamrun.results.catalogue import BUSY_THREADS, CPU_WAIT_PCT, FPS, RUNNABLE_THREADS
from slamrun.results.vocabulary import CONTENDABLE, OWN_WAIT_PER_THREAD_PCT

METHOD_ERROR = "method_error"  # in Launched.extra: (kind, message) of a method that failed before its process started


@dataclass(frozen=True)
class RunOutcome:
    state: str  # done | failed | cancelled
    values: dict  # ledger columns


@dataclass(frozen=True)
class Launched:
    """A run whose process has ended (not cancelled): what finish_attempt needs next."""

    result: ExecResult
    started: float
    extra: dict


def launch_run(
    run: PlannedRun,
    method: Method,
    view: PreparedView,
    backend: Backend,
    paths: RunPaths,
    attempt: int,
    cancel: threading.Event,
    cpus: tuple[int, ...] | None = None,
    memory_mb: int | None = None,
    log_cap_bytes: int = 20 * 2**20,
    max_output_bytes: int | None = None,
    campaign: str = "",
    on_start=None,
    results_id: str = "",
) -> Launched | RunOutcome:
    """Configure the run and run its process to its end (a RunOutcome only when cancelled). A full disk
    anywhere is a StorageError and any other OSError an InfraError (the machine's fault, not the method's);
    the run's staging folder is removed either way, except when the Docker daemon went away mid-run (the
    next start may collect the finished container)."""
    with _os_errors_as_infra(run, paths, attempt):
        paths.clear_staging(up_to=attempt)
        stage = paths.staging(attempt)
        raw = RunPaths.raw(stage)
        raw.mkdir(parents=True)
        started = time.time()
        pview, pwork = backend.process_paths(view, raw)  # as the method's process sees them
        try:  # the method's own calls: what they raise (a plug-in's bug too) is its failure, recorded as a result
            _write_config(raw, config_files(method, pview, pwork))
            argv = method.command(pview, pwork)
            env = method.environment()
        except MethodFailure as exc:
            RunPaths.log(stage).write_text(f"slamrun: the run was not started: {exc}\n")
            failed = {"backend": backend.name, "engine": backend.engine, METHOD_ERROR: [exc.kind, str(exc)]}
            return Launched(ExecResult(exit_code=None, wall_s=0.0), started, failed)
        labels = {
            "slamrun.campaign": campaign,
            "slamrun.results": results_id,  # which results folder: another folder's run of the campaign is not ours
            "slamrun.run": run.key.id,
            "slamrun.attempt": str(attempt),
        }
        req = ExecRequest(
            argv=argv,
            workdir=raw,
            view=view,
            log_path=RunPaths.log(stage),
            resources_path=RunPaths.resources(stage),
            timeout_s=run.timeout_s,
            cpus=cpus,
            memory_mb=memory_mb,
            log_cap_bytes=log_cap_bytes,
            max_output_bytes=max_output_bytes,
            image=method.image,
            needs_gpu=method.needs_gpu,
            modules=method.modules,
            env=env,
            labels=labels,
            token=paths.token(attempt),
        )
        try:
            result = backend.execute(req, cancel, on_start)
        except BackendUnreachable:
            raise  # the staging folder stays: the container may finish without the daemon
        except InfraError:
            shutil.rmtree(stage, ignore_errors=True)
            raise
        if result.cancelled:
            shutil.rmtree(stage, ignore_errors=True)
            return RunOutcome("cancelled", {})
        extra = _launch_record(argv, cpus, backend, method, result)
        return Launched(result, started, extra)


def _write_config(raw: Path, files: list[tuple[Path, str | bytes]]) -> None:
    for rel, content in files:
        target = raw / rel
        target.parent.mkdir(parents=True, exist_ok=True)
        if isinstance(content, bytes):
            target.write_bytes(content)
        else:
            target.write_text(content)


def _launch_record(argv: list[str], cpus, backend: Backend, method: Method, result: ExecResult) -> dict:
    """What ran where, for run.json: the argv, CPUs, backend and engine, the machine, the packages, native build or
    image."""
    extra = {"argv": argv, "cpus": list(cpus) if cpus else None, "backend": backend.name}
    extra["engine"] = backend.engine
    extra["machine"] = result.machine or machine()  # a Dask worker's own, else this one
    if backend.name == "local" and method.modules:  # in an image, the image's labels say what it holds
        versions = result.packages if result.packages is not None else package_versions(method.modules)
        extra["package_versions"] = versions
    if backend.name == "local" and (built := method.build_record()) is not None:
        extra["native_build"] = built  # its source, patches, targets, network
    if method.image and (image := backend.describe_image(method.image)) is not None:
        extra["image"] = image  # its sources, vocabulary, weights
    return extra


def finish_attempt(
    run: PlannedRun,
    method: Method,
    view: PreparedView,
    paths: RunPaths,
    attempt: int,
    result: ExecResult,
    started: float,
    groundtruth: Trajectory | None,
    extra: dict,
    contention_pct: float | None = None,
) -> RunOutcome:
    """What a finished process left in its staging folder, read, evaluated, recorded in run.json and renamed
    into place. Also used to collect a container that finished while the Docker daemon was away. A loss with
    more CPU wait than `contention_pct` is raised as Contended (the machine's load), never recorded as the method's."""
    with _os_errors_as_infra(run, paths, attempt):
        stage = paths.staging(attempt)
        raw = RunPaths.raw(stage)
        log_tail = tail(RunPaths.log(stage))
        extra = dict(extra)
        failure, message, traj = _judged(extra.pop(METHOD_ERROR, None), result, method, raw, view, log_tail)
        _not_the_methods_fault(run, method, view, stage, failure, message, log_tail)
        values: dict = {"exit_code": result.exit_code, **result.resources, "method_failure": failure}
        values["host"] = (extra.get("machine") or {}).get("name")
        values["packages"] = packages_text(extra.get("package_versions") or {})
        values["slamrun_commit"] = source_commit()  # the code that ran it
        values["eval_settings"] = run.evaluation.text()
        detail = ""
        if traj is None or not len(traj):
            values[FPS] = None  # frames per second of processing: nothing was processed to a pose
        else:
            write_tum(RunPaths.trajectory(stage), traj)
            figures, detail = evaluate_trajectory(traj, groundtruth, run_frames_of(run, method, view), run.evaluation)
            values.update(figures)
        settle(values, failure, message, detail, run.evaluation)
        values["cpu_wait_own_pct"] = own_wait_pct(method, extra.get("cpus"), values)
        _not_contended(run, stage, values, contention_pct, values["cpu_wait_own_pct"])
        if traj is not None and traj.report.n_nonfinite_dropped and not values["message"]:
            values["message"] = f"{traj.report.n_nonfinite_dropped} NaN or infinite row(s) of the output dropped"
        state = "failed" if values["failure"] else "done"
        values["ended_at"] = time.time()
        record = _record(run, method, view, attempt, started, result, traj, state, extra, values)
        RunPaths.run_json(stage).write_text(jsonio.dumps(record, indent=1))
        return _placed(paths, stage, run, state, values)


def _judged(refused, result: ExecResult, method: Method, raw: Path, view: PreparedView, log_tail: str):
    """(failure, message, trajectory) of a finished process; a method that filled the disk is `output_limit`, its
    output removed (it may not keep the disk)."""
    if refused:  # the method failed before its process could start
        failure, message, traj = refused[0], refused[1], None
    else:
        try:
            failure, message, traj = _classify(result, method, raw, view, log_tail)
        except MethodFailure as exc:  # a plug-in's accepts_exit or failure_from_log raised
            failure, message, traj = exc.kind, str(exc), None
    if failure and failure != "output_limit" and _out_of_space(raw, log_tail):
        if (size := folder_bytes(raw)) >= disk_reserve_bytes(raw):  # it filled the disk itself
            failure, message, traj = "output_limit", f"it filled the disk ({size / 2**20:.0f} MB written)", None
    if failure == "output_limit":
        shutil.rmtree(raw, ignore_errors=True)
        raw.mkdir()
    return failure, message, traj


def _not_the_methods_fault(
    run: PlannedRun, method: Method, view: PreparedView, stage: Path, failure, message, log_tail: str
) -> None:
    """A failure the machine caused is raised as such, never charged: the disk full under the method (StorageError),
    the machine lacking what the method needs, as its log says (its infra_pattern), or its input view changed during
    the run (InfraError)."""
    if failure and failure != "output_limit" and _out_of_space(RunPaths.raw(stage), log_tail):
        shutil.rmtree(stage, ignore_errors=True)
        raise StorageError(f"{run.key.id}: the disk is full ({failure}: {message})")
    lacking = method.infra_from_log(log_tail) if failure and failure not in ("timeout", "output_limit") else None
    if lacking:  # the method said the machine lacks what it needs (no GPU, too little GPU memory)
        shutil.rmtree(stage, ignore_errors=True)
        raise InfraError(f"{run.key.id}: {lacking[:300]}; not charged to the method")
    if failure and failure != "timeout":  # failed on an input that went missing or changed under it?
        damaged = verify_view(view.root, view.build_id)  # the build it started with, whole
        if damaged:
            shutil.rmtree(stage, ignore_errors=True)
            raise InfraError(f"{run.key.id}: its input view changed during the run ({damaged}); not charged")


def run_frames_of(run: PlannedRun, method: Method, view: PreparedView) -> Frames:
    """The run's frames: the sequence's, its view's and those its method takes with its parameters (a frame_drop
    view's dropped frames are the sequence's, read from its folder)."""
    view_times = view.original_timestamps()
    if run.perturbation.kind == "frame_drop":
        from slamrun.datasets.layouts import open_sequence

        sequence_times = open_sequence(run.sequence_dir).timestamps
    else:
        sequence_times = view_times
    try:
        given = method.frames_given(len(view_times))
    except MethodFailure:  # a plug-in's bug: its coverage is then of the view's frames
        given = None
    return run_frames(sequence_times, run.perturbation, run.key.direction, given)


def own_wait_pct(method: Method, cpus: list[int] | None, values: dict | None = None) -> float:
    """The CPU wait a run causes itself, the larger of two: a method with more busy threads than its lane has CPUs
    keeps its own threads waiting whatever else runs, OWN_WAIT_PER_THREAD_PCT per declared thread in excess
    (measured: ORB-SLAM3's 3 threads on 2 CPUs waited 32.5-58.4 % of their wall time on an idle machine, its threads
    busy in bursts); and what its tree measurably kept runnable beyond its CPUs (`tree_excess_pct`: a method that
    forks more busy workers than it declares). Where busy_threads() raises or gives no thread count (a plug-in's bug,
    found after its run: the run stands as it ended) the measured part alone, said in the run's message."""
    from slamrun.methods.base import busy_threads_of

    n = len(cpus) if cpus else len(os.sched_getaffinity(0))
    measured = tree_excess_pct(values or {}, n)
    busy, why = busy_threads_of(method)
    if why is not None:
        if values is not None:
            note = f"{why}; own-wait allowance taken as its measured excess alone"
            values["message"] = "; ".join(filter(None, [values.get("message"), note]))
        return measured
    if values is not None:
        values[BUSY_THREADS] = busy
    return max(OWN_WAIT_PER_THREAD_PCT * max(0, (busy or 0) - n), measured)


def tree_excess_pct(values: dict, cpus: int) -> float:
    """The wait a run's own process tree made certain: its threads runnable on average (`runnable_threads`, the
    monitor's: its CPU time and its wait, over its wall time) beyond the `cpus` of its lane cannot all run at once,
    whatever else the machine runs; that excess, in % of the wall time, is its own (its CPUs were busy with its own
    work), never the machine's load."""
    runnable = values.get(RUNNABLE_THREADS)
    if runnable is None:
        return 0.0
    return max(0.0, 100.0 * (runnable - cpus))


def _not_contended(
    run: PlannedRun, stage: Path, values: dict, contention_pct: float | None, own_pct: float = 0.0
) -> None:
    """A loss while the run's threads waited for a CPU longer than `contention_pct` of its wall time beyond the wait
    it causes itself (`own_pct`: own_wait_pct) is raised as Contended (its attempt removed), to be retried; a loss
    with less wait stays the method's."""
    wait = values.get(CPU_WAIT_PCT)
    if contention_pct is None or values["failure"] not in CONTENDABLE or wait is None:
        return
    if wait - own_pct <= contention_pct:
        return
    shutil.rmtree(stage, ignore_errors=True)
    beyond = f", {own_pct:.0f} % of it its own threads' (more than its CPUs)" if own_pct else ""
    pressure = values.get("host_cpu_pressure_pct")
    machine = f"; the machine's CPU pressure {pressure:.0f} %" if pressure is not None else ""
    raise Contended(
        f"{run.key.id}: {values['failure']} while its threads waited for a CPU {wait:.0f} % of its wall time{beyond} "
        f"(over contention_pct {contention_pct:g}{machine}): the machine's load, not charged to the method"
    )


def _record(
    run: PlannedRun,
    method: Method,
    view: PreparedView,
    attempt: int,
    started: float,
    result: ExecResult,
    traj: Trajectory | None,
    state: str,
    extra: dict,
    values: dict,
) -> dict:
    """The run's run.json: what ran, on what, and what came out."""
    return {
        "key": run.key.id,
        "method": run.key.label,  # its label: the ledger's and results.csv's names
        "method_name": run.method,
        "dataset": run.dataset,
        "sequence": run.key.sequence,
        "data": run.key.data,
        "direction": run.key.direction.value,
        "perturbation": run.perturbation.name,  # how the view's frames were made worse (none: the baseline)
        "level": run.perturbation.level,
        "perturbation_seed": run.perturbation.seed,
        "trial": run.key.trial,
        "seed": run.seed,  # the trial's seed the plan derived (params holds it too), None where the spec fixed it
        "settings": run.key.settings,
        "params": method.params.model_dump(mode="json"),
        "provider": slamrun.methods.provider_record(run.method),  # which package's implementation made this run
        "status": state,
        "attempt": attempt,
        "started_at": started,
        "view": str(view.root),
        "sequence_dir": str(run.sequence_dir),
        "timed_out": result.timed_out,
        "oom": result.oom,
        "log_truncated": result.log_truncated,
        "trajectory_report": traj.report.__dict__ if traj is not None else None,
        **extra,
        **values,
    }


def _placed(paths: RunPaths, stage: Path, run: PlannedRun, state: str, values: dict) -> RunOutcome:
    """The staging folder renamed into the run's folder; a run that finished in an earlier attempt stands."""
    final = paths.final
    if final.exists():  # a finished run is never overwritten
        earlier = finished_record(final, run.key.id)
        if earlier is not None:  # it finished in an earlier attempt: that one stands, this one is dropped
            shutil.rmtree(stage, ignore_errors=True)
            return RunOutcome(earlier["status"], {**earlier, "run_dir": str(final)})
        final.rename(final.with_name(f".{final.name}.incomplete-{int(time.time())}"))  # kept for a look
    final.parent.mkdir(parents=True, exist_ok=True)
    os.rename(stage, final)
    values["run_dir"] = str(final)
    return RunOutcome(state, values)


def config_files(method: Method, view: PreparedView, workdir: Path) -> list[tuple[Path, str | bytes]]:
    """The method's config files (`configure`), each checked before any is written: a path that is absolute or
    leads out with '..' would be written outside the run's work folder, so it is refused as the method's failure
    (MethodFailure 'crashed', naming the method, a plug-in with its package)."""
    files = method.configure(view, workdir)
    who = slamrun.methods.describe(method.name)
    if not isinstance(files, dict):
        raise MethodFailure("crashed", f"{who}: configure() returned a {type(files).__name__}, not {{path: content}}")
    out = []
    for rel, content in files.items():
        if why := config_path_problem(rel):
            raise MethodFailure("crashed", f"{who}: configure() returned the path {rel!r}: {why}; nothing was written")
        if not isinstance(content, str | bytes):
            raise MethodFailure(
                "crashed", f"{who}: configure() gave {rel!r} a {type(content).__name__}, not text or bytes"
            )
        out.append((Path(rel), content))
    return out


def config_path_problem(rel) -> str | None:
    """Why `rel` is not a file path inside a run's work folder, or None."""
    if not isinstance(rel, str | os.PathLike):
        return "not a path"
    path = Path(rel)
    if path.is_absolute():
        return "an absolute path, outside the run's work folder"
    if ".." in path.parts:
        return "'..' leads outside the run's work folder"
    if not path.parts:
        return "no file name"
    return None


@contextmanager
def _os_errors_as_infra(run: PlannedRun, paths: RunPaths, attempt: int) -> Iterator[None]:
    try:
        yield
    except OSError as exc:
        paths.clear_staging(up_to=attempt)
        if why := storage_problem(exc):
            raise StorageError(f"{run.key.id}: {why} ({exc})", why) from None
        raise InfraError(f"{run.key.id}: {exc}") from None


def _classify(
    result, method: Method, raw: Path, view: PreparedView, log_tail: str
) -> tuple[str | None, str | None, Trajectory | None]:
    """(failure kind or None, message, trajectory or None) from what the process left behind."""
    if result.output_exceeded:
        return "output_limit", f"stopped: {result.output_exceeded}; its output was removed", None
    if result.oom:
        return "oom", "killed: out of memory", None
    if result.timed_out:
        traj = _try_read(method, raw, view)
        return "timeout", f"killed at the timeout ({result.wall_s:.0f} s)", traj
    if not method.accepts_exit(result.exit_code, raw):
        kind = method.failure_from_log(log_tail) or "crashed"
        last = " | ".join(line.strip() for line in log_tail.strip().splitlines()[-3:])
        return kind, f"exit code {result.exit_code}: {last[-300:]}", _try_read(method, raw, view)
    try:
        traj = method.read_trajectory(raw, view)
    except MethodFailure as exc:
        return method.failure_from_log(log_tail) or exc.kind, str(exc), None
    except TrajectoryFormatError as exc:
        return "no_output", f"unreadable output: {exc}", None
    foreign = foreign_timestamps(traj, view)
    if foreign:
        return "bad_timestamps", foreign, traj
    if method.failure_from_log(log_tail) == "lost":
        return "lost?", "the method reported it was lost", traj
    return None, None, traj


def foreign_timestamps(traj: Trajectory, view: PreparedView, tol_s: float = ASSOCIATION_TOLERANCE_S) -> str | None:
    """Why a trajectory's poses are not at the sequence's frame times (more than `tol_s` from every frame of
    times.txt), or None when each pose is at a frame."""
    return foreign_timestamps_of(traj, view.original_timestamps(), tol_s)


def foreign_timestamps_of(traj: Trajectory, frames: np.ndarray, tol_s: float = ASSOCIATION_TOLERANCE_S) -> str | None:
    """Why a trajectory's poses are not at the frame times `frames` (increasing), or None when each pose is."""
    if not len(traj) or not len(frames):
        return None
    t = traj.timestamps
    distance = nearest(frames, t)[1]
    far = np.flatnonzero(distance > tol_s)
    if not len(far):
        return None
    first = far[0]
    return (
        f"{len(far)} of {len(t)} poses are at times that are not frame times of the sequence's times.txt "
        f"(first at t={float(t[first]):.6f}, {1000 * float(distance[first]):.1f} ms from the nearest frame)"
    )


def _out_of_space(folder: Path, log_tail: str) -> bool:
    """The method's log says so, or its work folder's filesystem has (almost) no space left."""
    return "No space left on device" in log_tail or shutil.disk_usage(folder).free < 2**20


def _try_read(method: Method, raw: Path, view: PreparedView) -> Trajectory | None:
    try:
        return method.read_trajectory(raw, view)
    except (MethodFailure, TrajectoryFormatError):
        return None
