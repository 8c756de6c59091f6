"""Metrics of many trajectory files against one ground truth, on every core.

The files are cut into chunks that worker processes read and evaluate (batched reading of TUM files, see
trajectory.read_tum_many); results come back in input order, each file's error as that file's result.
One job runs in this process. The numbers are the same whatever the number of jobs.
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

from runner.core import metrics
from runner.core.evaluation import TumMonoResult, tum_mono_file, tum_mono_many
from runner.core.trajectory import Trajectory, read_kitti, read_tum_many
from runner.errors import MetricError, TrajectoryFormatError
from runner.results.vocabulary import EVALUATE_FIELDS

METRICS = ("tum-mono", "ate", "rpe", "kitti")
GROUP = 32  # TUM-Mono estimates evaluated together (their arrays stay in the CPU's cache)


@dataclass(frozen=True)
class Options:
    """Which metric, and how: the alignment, RPE's step, the association tolerance; estimates as TUM files, or
    as KITTI pose files whose rows are the frames at `times`."""

    metric: str = "tum-mono"
    alignment: str = "sim3"
    delta: float = 1.0
    delta_unit: str = "frames"
    tolerance_s: float = metrics.DEFAULT_TOLERANCE_S
    est_format: str = "tum"
    times: tuple[float, ...] | None = None


def evaluate_one(gt: Trajectory, traj: Trajectory, opts: Options) -> dict:
    """One estimate's figures for `opts.metric` (status ok), or its status and why not."""
    if opts.metric == "tum-mono":
        return _tum_mono_fields(tum_mono_file(gt, traj))
    try:
        if opts.metric == "ate":
            res = metrics.ate(gt, traj, opts.alignment, opts.tolerance_s)
        elif opts.metric == "rpe":
            res = metrics.rpe(gt, traj, opts.delta, opts.delta_unit, opts.alignment, opts.tolerance_s)
        elif opts.metric == "kitti":
            res = metrics.kitti(gt, traj, opts.alignment, tolerance_s=opts.tolerance_s)
        else:
            raise MetricError(f"unknown metric {opts.metric!r}; known: {', '.join(METRICS)}")
    except MetricError as exc:
        return {"status": "failed", "n_poses": len(traj), "detail": str(exc)}
    return {"status": "ok", "n_poses": len(traj), **res.to_dict()}


def _tum_mono_fields(res: TumMonoResult) -> dict:
    d = res.to_dict()
    detail = {"detail": d["detail"]} if d["status"] != "ok" and d["detail"] else {}
    return {k: d.get(k) for k in EVALUATE_FIELDS} | detail


def _read(paths: Sequence[str | Path], opts: Options) -> list[Trajectory | TrajectoryFormatError]:
    if opts.est_format == "tum":
        return read_tum_many(paths)
    out: list[Trajectory | TrajectoryFormatError] = []
    for p in paths:
        try:
            out.append(read_kitti(p, np.asarray(opts.times)))
        except TrajectoryFormatError as exc:
            out.append(exc)
    return out


def evaluate_one_chunk(paths: Sequence[str | Path], gt: Trajectory, opts: Options = Options()) -> list[dict]:
    """Each file's result, in order; TUM-Mono's metric for `GROUP` files at a time (`tum_mono_many`)."""
    out: list[dict] = []
    group: list[tuple[str | Path, Trajectory]] = []

    def flush() -> None:
        for (path, _), res in zip(group, tum_mono_many(gt, [t for _, t in group]), strict=True):
            out.append({"file": str(path), **_tum_mono_fields(res)})
        group.clear()

    for path, traj in zip(paths, _read(paths, opts), strict=True):
        if isinstance(traj, TrajectoryFormatError):
            flush()
            d = {"status": "unreadable", "detail": str(traj)}
            if opts.metric == "tum-mono":  # every figure present, null
                d = dict.fromkeys(EVALUATE_FIELDS) | d
            out.append({"file": str(path), **d})
        elif opts.metric == "tum-mono":
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
