"""Metrics of many trajectory files against one ground truth, on every core.

The files are cut into chunks that worker processes read and evaluate (batched reading of TUM files, see
trajectory.read_tum_many); results come back in input order, each file's error as that file's result.
One job runs in this process. The numbers are the same whatever the number of jobs.

A file that is not a regular file (a FIFO, a device such as /dev/zero) or is larger than MAX_FILE_BYTES is
refused unread, as that file's result. With `Options.campaign` (a campaign's own per-run evaluation, given by the
caller), each file is evaluated exactly as a campaign evaluates a run.
"""

from __future__ import annotations

import ctypes
import os
from collections.abc import Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from multiprocessing import get_context
from pathlib import Path

import numpy as np

from slamrun.core import metrics
from slamrun.core.formats import read_trajectory
from slamrun.core.inputs import regular_file_problem
from slamrun.core.metric_table import METRICS, NO_PAIRS, Context, Metric, campaign_figures
from slamrun.core.metric_table import metric as metric_named
from slamrun.core.metrics import DEFAULT_TOLERANCE_S
from slamrun.core.trajectory import Trajectory, read_tum_many
from slamrun.errors import TrajectoryFormatError
from slamrun.results.catalogue import N_POSES
from slamrun.results.vocabulary import EvalStatus

GROUP = 32  # estimates of a metric with a batched form (TUM-Mono's) evaluated together (their arrays stay in cache)
MAX_FILE_BYTES = 256 * 2**20  # a trajectory or ground-truth file: a million poses are about 100 MB
# the figures a campaign records per metric (results.csv's columns)
CAMPAIGN_FIELDS = {name: m.columns for name, m in METRICS.items()}


@dataclass(frozen=True)
class Options:
    """Which metrics, and how: the alignment, RPE's interval, the association tolerance; estimates as TUM files, or
    as KITTI pose files whose rows are the frames at `times`; `frame_times`, the sequence's frames (RPE in frames
    counts them). With `campaign`, each file is evaluated as a campaign evaluates a run (metric_table.campaign_figures:
    its metrics, alignment and association) instead."""

    metrics: tuple[str, ...] = ("tum-mono",)
    alignment: str = "sim3"
    delta: float = 1.0
    delta_unit: str = "s"
    tolerance_s: float = DEFAULT_TOLERANCE_S
    est_format: str = "tum"
    times: tuple[float, ...] | None = None
    frame_times: tuple[float, ...] | None = None
    campaign: bool = False

    @property
    def frames(self) -> np.ndarray | None:
        return None if self.frame_times is None else np.asarray(self.frame_times, float)


def file_problem(path: str | Path, limit: int, what: str) -> str | None:
    """Why `path` is not a file slamrun may read whole (not a regular file, or more than `limit` bytes), or None.
    Never opens it, so never blocks."""
    if problem := regular_file_problem(Path(path), what):
        return problem
    size = os.stat(path).st_size
    if size > limit:
        return f"{path}: {size:,} bytes; {what} is at most {limit:,} bytes"
    return None


def evaluate_one(gt: Trajectory, traj: Trajectory, opts: Options) -> dict:
    """One estimate's figures for `opts.metrics` (status ok), or its status and why not."""
    if opts.campaign:
        return _campaign_fields(gt, traj, opts)
    if len(opts.metrics) > 1:
        return _merged(gt, traj, opts)
    d = _single(gt, traj, opts.metrics[0], opts)
    return d | {"status": "failed"} if d["status"] == NO_PAIRS else d


def _single(gt: Trajectory, traj: Trajectory, metric: str, opts: Options) -> dict:
    ctx = Context(opts.alignment, opts.tolerance_s, opts.delta, opts.delta_unit, opts.frames)
    return metric_named(metric).of_file(gt, traj, ctx)


def _campaign_fields(gt: Trajectory, traj: Trajectory, opts: Options) -> dict:
    """The campaign's figures of one estimate: every field of the metrics asked for (null where missing). Its
    status is the campaign's eval_status, or failed where no figure at all came out."""
    interval = metrics.RpeInterval(opts.delta, opts.delta_unit)
    figures, detail = campaign_figures(gt, traj, opts.metrics, opts.alignment, interval, opts.frames)
    fields = {k: figures.get(k) for m in opts.metrics for k in CAMPAIGN_FIELDS[m]}
    status = figures.get("eval_status", EvalStatus.ok.value)
    if status == EvalStatus.ok.value and all(v is None for v in fields.values()):
        status = "failed"
    return {"status": status, N_POSES: len(traj), **fields} | ({"detail": detail} if detail else {})


def _merged(gt: Trajectory, traj: Trajectory, opts: Options) -> dict:
    """Several metrics of one estimate in one result: the first status that is not ok, every figure, each
    metric's reason."""
    out: dict = {"status": "ok", N_POSES: len(traj)}
    details = []
    for metric in opts.metrics:
        d = _single(gt, traj, metric, opts)
        status, detail = d.pop("status"), d.pop("detail", None)
        d.pop("metric", None)
        if status not in ("ok", NO_PAIRS) and out["status"] == "ok":  # too short for one metric: noted, as a
            # campaign notes it
            out["status"] = status
        if detail:
            details.append(f"{metric}: {detail}")
        out |= d
    return out | ({"detail": "; ".join(details)} if details else {})


def _unreadable(exc: TrajectoryFormatError, opts: Options) -> dict:
    """A file that could not be read: every figure it would have had present, null."""
    d = {"status": "unreadable", "detail": str(exc)}
    if opts.campaign:
        return {"status": "unreadable", **dict.fromkeys(k for m in opts.metrics for k in CAMPAIGN_FIELDS[m]), **d}
    if len(opts.metrics) == 1:
        return dict.fromkeys(("status", *metric_named(opts.metrics[0]).file_fields)) | d
    return d


def _batched(opts: Options) -> Metric | None:
    """The one metric asked for, where it evaluates many files at once (TUM-Mono's); else None."""
    if len(opts.metrics) != 1 or opts.campaign:
        return None
    m = metric_named(opts.metrics[0])
    return m if m.many is not None else None


def _read(paths: Sequence[str | Path], opts: Options) -> list[Trajectory | TrajectoryFormatError]:
    """Each file's trajectory or the error naming it; files that are not regular, or too large, unread."""
    refused = {i: p for i, path in enumerate(paths) if (p := file_problem(path, MAX_FILE_BYTES, "a trajectory file"))}
    readable = [path for i, path in enumerate(paths) if i not in refused]
    if opts.est_format == "tum":  # TUM files read in batches (the fast path), any other format one by one
        read = iter(read_tum_many(readable))
    else:
        read = iter([_read_one(p, opts) for p in readable])
    return [TrajectoryFormatError(refused[i]) if i in refused else next(read) for i in range(len(paths))]


def _read_one(path: str | Path, opts: Options) -> Trajectory | TrajectoryFormatError:
    try:
        return read_trajectory(path, opts.est_format, None if opts.times is None else np.asarray(opts.times))
    except (TrajectoryFormatError, ValueError) as exc:
        return exc if isinstance(exc, TrajectoryFormatError) else TrajectoryFormatError(f"{path}: {exc}")


def evaluate_one_chunk(paths: Sequence[str | Path], gt: Trajectory, opts: Options = Options()) -> list[dict]:
    """Each file's result, in order; a metric with a batched form (TUM-Mono's) for `GROUP` files at a time."""
    out: list[dict] = []
    group: list[tuple[str | Path, Trajectory]] = []
    batched = _batched(opts)

    def flush() -> None:
        if group:
            for (path, _), res in zip(group, batched.many(gt, [t for _, t in group]), strict=True):
                out.append({"file": str(path), **batched.file_dict(res)})
        group.clear()

    for path, traj in zip(paths, _read(paths, opts), strict=True):
        if isinstance(traj, TrajectoryFormatError):
            flush()
            out.append({"file": str(path), **_unreadable(traj, opts)})
        elif batched is not None:
            group.append((path, traj))
            if len(group) == GROUP:
                flush()
        else:
            out.append({"file": str(path), **evaluate_one(gt, traj, opts)})
    flush()
    return out


_GT: Trajectory | None = None  # the ground truth in a worker process
_OPTS = Options()


def _init(gt: Trajectory, opts: Options) -> None:
    global _GT, _OPTS
    _GT, _OPTS = gt, opts


def _chunk(paths: list[str]) -> list[dict]:
    return evaluate_one_chunk(paths, _GT, _OPTS)


def keep_freed_memory() -> None:
    """Tune glibc's allocator for a process that makes and frees the same large arrays file after file: they
    come from the heap, and freed memory stays for the next file. By default each array over 128 KB is mapped
    and unmapped, and every page of it faults again on first use (about 15 % of `slamrun evaluate`'s time on
    1,000 files). Inherited by the worker processes; nothing on a C library without mallopt."""
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return
    mallopt(-3, 32 << 20)  # M_MMAP_THRESHOLD: glibc's largest
    mallopt(-1, 256 << 20)  # M_TRIM_THRESHOLD: keep up to 256 MB freed at the top of the heap


def evaluate_files(
    gt: Trajectory, paths: Sequence[str | Path], jobs: int | None = None, opts: Options = Options()
) -> Iterator[dict]:
    """One result dict per file, in input order; `jobs` worker processes (default: every core)."""
    paths = [str(p) for p in paths]
    jobs = max(1, min(jobs or os.cpu_count() or 1, len(paths) or 1))
    if jobs == 1:
        yield from evaluate_one_chunk(paths, gt, opts)
        return
    size = max(8, min(256, len(paths) // (jobs * 4) or 1))
    chunks = [paths[i : i + size] for i in range(0, len(paths), size)]
    ctx = get_context("fork")
    with ProcessPoolExecutor(jobs, mp_context=ctx, initializer=_init, initargs=(gt, opts)) as pool:
        for results in pool.map(_chunk, chunks):
            yield from results
