"""KITTI odometry sequences: `sequences/NN/` with `image_0/` (the left grey camera, already rectified), `times.txt`
(seconds, one per frame) and `calib.txt` (P0: the 3x4 projection of camera 0); ground truth `poses/NN.txt` beside
`sequences/` (sequences 00-10): one 3x4 camera-to-world row per frame, no timestamps of its own. Written
synthetically with its poses beside the sequences' folder; not downloaded (its site asks each user to register).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from slamrun.core.camera import CameraFile, FovCamera
from slamrun.core.trajectory import Trajectory, from_matrices
from slamrun.datasets import frames
from slamrun.datasets.protocol import Layout, Placed
from slamrun.datasets.sequence import (
    IMAGE_SUFFIXES,
    MAX_POSITION_M,
    Sequence,
    camera_problem,
    folder_sequence,
    number_rows,
    raise_problems,
    read_text,
    require_regular,
    row_count,
    sequence_folder,
    time_problem,
)
from slamrun.errors import DatasetError

if TYPE_CHECKING:
    from slamrun.datasets.synth import Synth


def poses_path(root: Path) -> Path:
    """`poses/NN.txt` of sequence folder `sequences/NN`."""
    return root.parent.parent / "poses" / f"{root.name}.txt"


def open_kitti(root: str | Path) -> Sequence:
    root = sequence_folder(root)
    times_path, calib, images, gt_path = root / "times.txt", root / "calib.txt", root / "image_0", poses_path(root)
    require_regular(root, "KITTI", [times_path, calib, gt_path])
    problems: list[str] = []
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
        n_poses = row_count(gt_path)
        if n_poses != len(times):
            problems.append(f"{gt_path}: {n_poses} poses but {len(times)} frames; KITTI's poses are one per frame")
    raise_problems(root, "KITTI", problems)
    assert camera is not None and times is not None

    def groundtruth() -> Trajectory:
        return read_poses(gt_path, times)

    return folder_sequence(root, "kitti", names, times, camera, images, (times_path, calib), gt_path, groundtruth)


def read_poses(path: Path, times: np.ndarray) -> Trajectory:
    """poses/NN.txt at the frames' times; every problem named with its line."""
    rows = []
    for n, values in number_rows(path, 12, "12 finite numbers (a 3x4 [R|t] row)"):
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


# ---------------------------------------------------------------------------------------------------- the layout


def recognise(root: Path) -> bool:
    """image_0/ or calib.txt."""
    return (root / "image_0").is_dir() or (root / "calib.txt").exists()


def synth_outside(out: Path) -> tuple[Path, ...]:
    """The synthetic sequence's poses: poses/NN.txt beside the sequences' folder."""
    return (poses_path(out),)


def write_synthetic(tmp: Path, s: Synth) -> Placed:
    """The sequence in KITTI's layout: image_0/NNNNNN.png, irregular-looking times about 10 Hz, calib.txt's P0-P3
    and Tr, and the camera poses relative to the first camera, staged beside the folder for poses/NN.txt."""
    import cv2

    from slamrun.core.camera import PinholeCamera
    from slamrun.datasets.synth import savetxt

    s = drive(s)
    w, h = s.size
    f = 0.55 * w
    cam = PinholeCamera(w, h, f, f, w / 2 - 0.5, h / 2 - 0.5)
    images = tmp / "image_0"
    images.mkdir()
    for i, img in s.images(cam):
        cv2.imwrite(str(images / f"{i:06d}.png"), img)
    t = np.arange(s.frames) * 0.1036  # about 10 Hz, KITTI's irregular-looking step
    (tmp / "times.txt").write_text("".join(f"{v:e}\n" for v in t))

    def p(tx: float) -> str:  # a 3x4 projection row-major, KITTI's %e style
        return " ".join(f"{v:e}" for v in (f, 0, cam.cx, tx, 0, f, cam.cy, 0, 0, 0, 1, 0))

    (tmp / "calib.txt").write_text(
        f"P0: {p(0.0)}\nP1: {p(-0.54 * f)}\nP2: {p(0.0)}\nP3: {p(-0.54 * f)}\nTr: 1 0 0 0 0 1 0 0 0 0 1 0\n"
    )
    poses = s.poses_at(s.scene, np.arange(s.frames) / max(s.frames - 1, 1))
    relative = np.linalg.inv(poses[0]) @ poses  # KITTI: camera poses in the first camera's frame
    rows = relative[:, :3, :].reshape(len(relative), 12)
    staged = tmp.parent / f".{s.name}.poses.tmp"
    savetxt(staged, rows, fmt="%e")
    return [(staged, tmp.parent.parent / "poses" / f"{s.name}.txt")]


KITTI_MIN_DRIVE_M = 120.0  # longer than KITTI's shortest segment (100 m), so that its metric has segments
FRAMES_PER_LAP = 100  # at least: a lap never goes faster than the plain loop over 100 frames


def drive(s):
    """KITTI's synthetic drive: in the courtyard (outdoor scale, whatever `scene` says: KITTI is a drive), as many
    laps as make it KITTI_MIN_DRIVE_M long where the frames allow one lap per FRAMES_PER_LAP (the default 300 frames
    drive two or three laps of 57-80 m, by seed; 60 frames drive one, and the report says that KITTI's segments
    need more)."""
    from dataclasses import replace

    from slamrun.datasets.synth import lap_length

    outdoor = replace(s, scene_kind="outdoor")
    laps = max(1, min(s.frames // FRAMES_PER_LAP, math.ceil(KITTI_MIN_DRIVE_M / lap_length(outdoor.scene))))
    return replace(outdoor, laps=laps)


KITTI_HOWTO = (
    "KITTI odometry is not downloaded by slamrun: its site (https://www.cvlibs.net/datasets/kitti/eval_odometry.php) "
    "asks each user to register and agree to its terms. Download data_odometry_gray.zip, data_odometry_calib.zip and "
    "data_odometry_poses.zip there, unpack them into one folder (they share dataset/sequences/NN/ and add "
    "dataset/poses/), and give a spec `layout: kitti` with `path: <folder>/dataset/sequences` and sequences such as "
    '["00", "05"] (ground truth for 00-10).'
)
LAYOUT = Layout(
    name="kitti",
    title="KITTI odometry (sequences/NN, the left grey camera; poses/NN.txt for 00-10)",
    recognise=recognise,
    frame_list="times.txt",
    read=open_kitti,
    groundtruth_file="poses/NN.txt beside sequences/",
    default_metrics=("ate", "rpe", "kitti"),
    synth=write_synthetic,
    synth_outside=synth_outside,
    manual_download=KITTI_HOWTO,
)
