"""KITTI odometry sequences: `sequences/NN/` with `image_0/` (the left grey camera, already rectified), `times.txt`
(seconds, one per frame) and `calib.txt` (P0: the 3x4 projection of camera 0); ground truth `poses/NN.txt` beside
`sequences/` (sequences 00-10): one 3x4 camera-to-world row per frame, no timestamps of its own.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from runner.core.camera import CameraFile, FovCamera
from runner.core.trajectory import Trajectory, from_matrices
from runner.datasets import frames
from runner.datasets.sequence import (
    IMAGE_SUFFIXES,
    MAX_POSITION_M,
    Sequence,
    camera_problem,
    check_regular,
    folder_sequence,
    read_text,
    time_problem,
)
from runner.errors import DatasetError


def poses_path(root: Path) -> Path:
    """`poses/NN.txt` of sequence folder `sequences/NN`."""
    return root.parent.parent / "poses" / f"{root.name}.txt"


def open_kitti(root: str | Path) -> Sequence:
    root = Path(root)
    if not root.is_dir():
        raise DatasetError(f"{root}: sequence folder not found")
    times_path, calib, images, gt_path = root / "times.txt", root / "calib.txt", root / "image_0", poses_path(root)
    problems = check_regular([times_path, calib, gt_path], {times_path, calib, gt_path})
    if problems:
        raise DatasetError(f"{root}: invalid KITTI sequence:\n  " + "\n  ".join(problems))
    for p, what in ((times_path, "one time in seconds per frame"), (calib, "P0: the 12 numbers of camera 0")):
        if not p.is_file():
            problems.append(f"{p}: missing; expected {what}")
    names = sorted(p.name for p in images.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES) if images.is_dir() else []
    if not names:
        problems.append(f"{images}: no frames (expected image_0/000000.png ...)")
    times = _read_times(times_path, problems) if times_path.is_file() else None
    camera = _read_calib(calib, problems) if calib.is_file() else None
    if names and times is not None and len(names) != len(times):
        problems.append(
            f"{times_path}: {len(times)} times but {len(names)} images in {images.name}/; expected one each"
        )
    if camera is not None and (problem := camera_problem(calib, camera)):
        problems.append(problem)
    elif names:  # every frame of the first one's size (which gives the camera's)
        size = (camera.camera.width, camera.camera.height) if camera is not None else None
        frames.check_files(images, names, size, problems, f"the first frame ({names[0]})")
    if gt_path.is_file() and times is not None and not problems:
        n_poses = sum(1 for line in read_text(gt_path).splitlines() if line.strip())
        if n_poses != len(times):
            problems.append(f"{gt_path}: {n_poses} poses but {len(times)} frames; KITTI's poses are one per frame")
    if problems:
        raise DatasetError(f"{root}: invalid KITTI sequence:\n  " + "\n  ".join(problems))
    assert camera is not None and times is not None

    def groundtruth() -> Trajectory:
        return read_poses(gt_path, times)

    return folder_sequence(root, "kitti", names, times, camera, images, (times_path, calib), gt_path, groundtruth)


def read_poses(path: Path, times: np.ndarray) -> Trajectory:
    """poses/NN.txt at the frames' times; every problem named with its line."""
    rows = []
    for n, line in enumerate(read_text(path).splitlines(), start=1):
        if not line.strip():
            continue
        try:
            values = [float(v) for v in line.split()]
        except ValueError:
            raise DatasetError(f"{path}:{n}: not numbers: {line.strip()[:60]!r}") from None
        if len(values) != 12 or not np.isfinite(values).all():
            raise DatasetError(f"{path}:{n}: {len(values)} values; expected 12 finite numbers (a 3x4 [R|t] row)")
        _check_pose(path, n, np.array(values).reshape(3, 4))
        rows.append(values)
    if len(rows) != len(times):
        raise DatasetError(f"{path}: {len(rows)} poses but {len(times)} frames; KITTI's poses are one per frame")
    return from_matrices(times, np.array(rows).reshape(-1, 3, 4))


def _check_pose(path: Path, n: int, pose: np.ndarray) -> None:
    """A ground-truth row: a rotation (orthonormal within 0.01; KITTI's are within 1e-6) and a position within
    MAX_POSITION_M of the origin."""
    far = np.abs(pose[:, 3]) > MAX_POSITION_M
    if far.any():
        raise DatasetError(
            f"{path}:{n}: a position of {pose[:, 3][far][0]:g} m; ground truth must be finite and within "
            f"{MAX_POSITION_M:.0e} m of the origin"
        )
    r = pose[:, :3]
    if np.abs(r @ r.T - np.eye(3)).max() > 0.01:
        raise DatasetError(f"{path}:{n}: its 3x3 part is not a rotation (not orthonormal)")


def _read_times(path: Path, problems: list[str]) -> np.ndarray | None:
    out = []
    for n, line in enumerate(read_text(path).splitlines(), start=1):
        if not line.strip():
            continue
        token = line.split()[0]
        try:
            out.append(float(token))
        except ValueError:
            problems.append(f"{path}:{n}: {line.strip()[:60]!r} is not a time in seconds")
            return None
        if problem := time_problem(path, n, token[:60], out[-1]):
            problems.append(problem)
            return None
    t = np.array(out)
    bad = np.flatnonzero(np.diff(t) <= 0)
    if not len(t):
        problems.append(f"{path}: empty")
        return None
    if len(bad):
        problems.append(f"{path}:{int(bad[0]) + 2}: times not strictly increasing")
        return None
    return t


def _read_calib(path: Path, problems: list[str]) -> CameraFile | None:
    """P0 of calib.txt → a pinhole camera (KITTI's images are rectified); the size comes from the first frame."""
    for n, line in enumerate(read_text(path).splitlines(), start=1):
        if line.startswith("P0:"):
            try:
                p = [float(v) for v in line[3:].split()]
            except ValueError:
                problems.append(f"{path}:{n}: P0 holds a value that is not a number")
                return None
            if len(p) != 12 or not np.isfinite(p).all() or p[0] <= 0 or p[5] <= 0:
                problems.append(
                    f"{path}:{n}: P0 is {' '.join(line[3:].split())[:120]!r}; expected 12 finite numbers with "
                    "positive focal lengths"
                )
                return None
            size = _first_frame_size(path.parent / "image_0")
            if size is None:
                return None
            w, h = size
            return CameraFile(FovCamera(w, h, p[0], p[5], p[2], p[6], 0.0), "none", w, h)
    problems.append(f"{path}: no 'P0:' line (the projection of camera 0)")
    return None


def _first_frame_size(images: Path) -> tuple[int, int] | None:
    """The first frame's size, from its header (or its decoding); None when it has none (the frames' check
    names the problem)."""
    if not images.is_dir():
        return None
    first = min((p for p in images.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES), default=None)
    if first is None or frames.frame_file_problem(first) is not None:
        return None
    head = frames.read_head(first)
    size = frames.header_size(head) if head else None
    if size is None:
        try:
            img = frames.decode(frames.read_frame(first), str(first), None)
        except DatasetError:
            return None
        size = (img.shape[1], img.shape[0])
    return size
