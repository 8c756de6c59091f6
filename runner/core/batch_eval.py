"""TUM-Mono metrics of many trajectory files against one ground truth, on every core.

The files are cut into chunks that worker processes read and evaluate (batched reading, see
trajectory.read_tum_many); results come back in input order, each file's error as that file's result.
One job runs in this process. The numbers are the same whatever the number of jobs.
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path

from runner.core.evaluation import tum_mono_file
from runner.core.trajectory import Trajectory, read_tum_many
from runner.errors import TrajectoryFormatError
from runner.results.vocabulary import EVALUATE_FIELDS

_GT: Trajectory | None = None  # the ground truth in a worker process


def evaluate_one_chunk(paths: Sequence[str | Path], gt: Trajectory) -> list[dict]:
    out = []
    for path, traj in zip(paths, read_tum_many(paths), strict=True):
        if isinstance(traj, TrajectoryFormatError):
            d = {"status": "unreadable", "detail": str(traj)}
        else:
            d = tum_mono_file(gt, traj).to_dict()
        detail = d.get("detail") if d["status"] != "ok" else None
        out.append(
            {"file": str(path), **{k: d.get(k) for k in EVALUATE_FIELDS}, **({"detail": detail} if detail else {})}
        )
    return out


def _init(gt: Trajectory) -> None:
    global _GT
    _GT = gt


def _chunk(paths: list[str]) -> list[dict]:
    return evaluate_one_chunk(paths, _GT)


def evaluate_files(gt: Trajectory, paths: Sequence[str | Path], jobs: int | None = None) -> Iterator[dict]:
    """One result dict per file, in input order; `jobs` worker processes (default: every core)."""
    paths = [str(p) for p in paths]
    jobs = max(1, min(jobs or os.cpu_count() or 1, len(paths) or 1))
    if jobs == 1:
        yield from evaluate_one_chunk(paths, gt)
        return
    size = max(8, min(256, len(paths) // (jobs * 4) or 1))
    chunks = [paths[i : i + size] for i in range(0, len(paths), size)]
    ctx = get_context("fork")
    with ProcessPoolExecutor(jobs, mp_context=ctx, initializer=_init, initargs=(gt,)) as pool:
        for results in pool.map(_chunk, chunks):
            yield from results
