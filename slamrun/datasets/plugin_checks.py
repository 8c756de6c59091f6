"""What a plug-in layout gives is checked as a built-in reader checks its files, before any run: a plug-in's bad
data is a dataset error naming the plug-in and its package, never charged to a method, and a slow or hung plug-in
call ends in a bounded time.

A built-in reader checks each value as it parses its files (`slamrun.datasets.sequence`); a plug-in's reader hands
over a finished `Sequence`, so the same rules are applied to that: frame names and times of one length, at most
MAX_FRAMES of them, times finite, within MAX_TIME_S and strictly increasing, exposures finite and positive, a
camera slamrun can rectify; its ground truth a `Trajectory` at the frames' times, finite where it has a pose, with
unit quaternions, and a pose at one frame at least.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import replace
from typing import TypeVar

import numpy as np

from slamrun.core.camera import CameraFile
from slamrun.core.trajectory import Trajectory
from slamrun.datasets.sequence import MAX_POSITION_M, MAX_TIME_S, Sequence, camera_problem
from slamrun.errors import DatasetError, one_line

# Far above any real sequence's frame count (KITTI 00: 4,541; the longest TUM-Mono: about 21,000), far below what
# would exhaust memory in a view's preparation (40 million times: 2 GB and 90 s before a method started).
MAX_FRAMES = 1_000_000
UNIT_QUATERNION_TOL = 1e-3  # |q| - 1: a unit quaternion written with 6 decimals is well inside
# How long a plug-in's function may take (s): recognising a folder is a look at its files; reading a sequence or
# its ground truth parses text files (a million frames: seconds); writing a synthetic one renders every frame.
TIME_LIMITS_S = {"recognise": 30.0, "read": 600.0, "groundtruth": 600.0, "synth": 3600.0, "other": 60.0}

T = TypeVar("T")


def bounded(fn: Callable[..., T], limit_s: float, who: str, what: str) -> Callable[..., T]:
    """`fn` run in a thread of its own, given `limit_s` seconds: past them, DatasetError naming the plug-in (the
    thread, a daemon, is left to end with the process: Python cannot stop it)."""

    def call(*args):
        box: dict = {}

        def target():
            try:
                box["value"] = fn(*args)
            except BaseException as exc:  # noqa: BLE001 - handed to the caller's thread, raised there
                box["error"] = exc

        worker = threading.Thread(target=target, name=f"plug-in {what}", daemon=True)
        worker.start()
        worker.join(limit_s)
        if worker.is_alive():
            where = f" on {args[0]}" if args else ""
            raise DatasetError(
                f"{who}: {what}{where} took more than {limit_s:g} s and was given up; the plug-in hangs or its "
                "data is far larger than a sequence's"
            )
        if "error" in box:
            raise box["error"]
        return box["value"]

    return call


def sequence_problems(seq: Sequence) -> list[str]:
    """Why the plug-in's `seq` cannot be run, as built-in readers would say it of their files (empty: it can)."""
    names = seq.frame_names
    if not isinstance(names, tuple) or not all(isinstance(n, str) and n for n in names):
        return ["its frame_names must be a tuple of frame file names"]
    n = len(names)
    if n == 0:
        return ["it has no frames"]
    if n > MAX_FRAMES:
        return [f"{n:,} frames, more than a sequence can have ({MAX_FRAMES:,})"]
    problems = _times_problems(seq.timestamps, n)
    if seq.exposures_ms is not None:
        exp = _vector(seq.exposures_ms)
        if exp is None or len(exp) != n:
            problems.append(f"its exposures must be one number per frame ({n})")
        elif not (np.isfinite(exp).all() and (exp > 0).all()):
            problems.append(f"exposure of frame {_first(~(np.isfinite(exp) & (exp > 0)))} is not a positive time (ms)")
    if not isinstance(seq.camera, CameraFile):
        problems.append(f"its camera is {type(seq.camera).__name__}, not a slamrun.core.camera.CameraFile")
    elif problem := camera_problem(seq.root, seq.camera):
        problems.append(problem)
    if (seq.zip_path is None) == (seq.images_dir is None):
        problems.append("exactly one of zip_path and images_dir must say where its frames are")
    return problems


def _times_problems(times, n: int) -> list[str]:
    t = _vector(times)
    if t is None:
        return ["its timestamps must be a 1-D array of numbers (seconds), one per frame"]
    if len(t) != n:
        return [f"{len(t)} timestamps for {n} frames; expected one per frame"]
    if not np.isfinite(t).all():
        return [f"the time of frame {_first(~np.isfinite(t))} is not a finite number of seconds"]
    if (np.abs(t) > MAX_TIME_S).any():
        return [f"the time of frame {_first(np.abs(t) > MAX_TIME_S)} is beyond {MAX_TIME_S:.0e} s"]
    if n > 1 and not (np.diff(t) > 0).all():
        k = _first(np.diff(t) <= 0) + 1
        return [f"frame times must increase: frame {k} at {t[k]:.9f} s follows {t[k - 1]:.9f} s"]
    return []


def _vector(values) -> np.ndarray | None:
    """`values` as a 1-D float array, or None when they are not one."""
    try:
        arr = np.asarray(values, dtype=float)
    except (TypeError, ValueError):
        return None
    return arr if arr.ndim == 1 else None


def _first(mask: np.ndarray) -> int:
    return int(np.flatnonzero(mask)[0])


def groundtruth_problem(gt, seq: Sequence) -> str | None:
    """Why the plug-in's ground truth `gt` for `seq` cannot be evaluated against, or None."""
    if not isinstance(gt, Trajectory):
        return f"its ground truth is {type(gt).__name__}, not a slamrun.core.trajectory.Trajectory"
    n = seq.n_frames
    if len(gt) != n or np.shape(gt.positions) != (n, 3) or np.shape(gt.quaternions) != (n, 4):
        return f"its ground truth has {len(gt)} poses for {n} frames; expected one per frame (NaN where none)"
    if not np.array_equal(np.asarray(gt.timestamps, float), np.asarray(seq.timestamps, float)):
        return "its ground truth is not at the frames' times (expected a pose per frame, at that frame's time)"
    pos, quat = np.asarray(gt.positions, float), np.asarray(gt.quaternions, float)
    missing = np.isnan(pos).all(axis=1) & np.isnan(quat).all(axis=1)  # a frame without a pose: every value NaN
    if not (np.isfinite(pos[~missing]).all() and np.isfinite(quat[~missing]).all()):
        bad = _first(~missing & ~(np.isfinite(pos).all(axis=1) & np.isfinite(quat).all(axis=1)))
        return f"its ground-truth pose at frame {bad} holds NaN or an infinity (a frame without a pose: all NaN)"
    if (np.abs(pos[~missing]) > MAX_POSITION_M).any():
        return f"a ground-truth position is beyond {MAX_POSITION_M:.0e} m of the origin"
    norms = np.linalg.norm(quat[~missing], axis=1)
    if (np.abs(norms - 1) > UNIT_QUATERNION_TOL).any():
        k = _first(~missing & (np.abs(np.linalg.norm(np.nan_to_num(quat), axis=1) - 1) > UNIT_QUATERNION_TOL))
        return f"its ground-truth quaternion at frame {k} has norm {np.linalg.norm(quat[k]):.6g}; expected 1"
    if missing.all():
        return f"its ground truth has no pose at any of the {n} frames"
    return None


def checked_reader(read: Callable[..., Sequence], who: str) -> Callable[..., Sequence]:
    """The plug-in's `read`, bounded in time, whose Sequence passes `sequence_problems` and whose ground-truth
    reader (bounded too) passes `groundtruth_problem`: DatasetError naming the plug-in and the folder otherwise."""
    read = bounded(read, TIME_LIMITS_S["read"], who, "reading the sequence")

    def reader(root):
        seq = read(root)
        if not isinstance(seq, Sequence):
            raise DatasetError(f"{who}: its reader gave {type(seq).__name__} for {root}, not a Sequence")
        problems = sequence_problems(seq)
        if problems:
            raise DatasetError(f"{who}: the sequence it read from {root} cannot be run: " + "; ".join(problems))
        if seq.groundtruth_reader is None:
            return seq
        if seq.groundtruth_path is None:
            raise DatasetError(f"{who}: the sequence it read from {root} has a ground-truth reader but no file")
        gt_read = bounded(seq.groundtruth_reader, TIME_LIMITS_S["groundtruth"], who, "reading the ground truth")

        def groundtruth() -> Trajectory:
            try:
                gt = gt_read()
            except DatasetError:
                raise
            except (KeyboardInterrupt, SystemExit):
                raise
            except BaseException as exc:  # noqa: BLE001 - someone else's package: named, never a traceback
                raise DatasetError(
                    f"{who}: reading the ground truth {seq.groundtruth_path} failed: {one_line(exc)}"
                ) from None
            if problem := groundtruth_problem(gt, seq):
                raise DatasetError(f"{who}: {seq.groundtruth_path}: {problem}")
            return gt

        return replace(seq, groundtruth_reader=groundtruth)

    return reader
