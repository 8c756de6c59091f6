"""TartanAir (v1), one trajectory's folder (`ENV/Easy/P000/`): `image_left/NNNNNN_left.png` (640x480 colour, numbered
from 000000 without gaps) and `pose_left.txt` (`tx ty tz qx qy qz qw`, one row per frame, no times). The camera is
the published pinhole: fx = fy = 320, cx 320, cy 240, no distortion.

Poses are in the NED convention: the camera's own axes x forward, y right, z down, in a world whose axes are NED
too. slamrun carries them to the camera convention methods use (x right, y down, z forward) as TartanAir's own
evaluation does (tartanair_tools, `ned2cam`): each pose T becomes M T M^-1 with M = [[0,1,0],[0,0,1],[1,0,0]],
which maps NED's (forward, right, down) to (right, down, forward), in the camera and the world alike.

Times: TartanAir publishes none (its poses are sampled along a path, not recorded in time). slamrun takes frame k at
k / 20 s: its authors suggest assuming 10-30 Hz and sized the trajectories' speeds for 20 Hz.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from slamrun.core.camera import CameraFile, FovCamera
from slamrun.core.trajectory import Trajectory, quat_to_rotmat, rotmat_to_quat
from slamrun.datasets import file_notes, frames
from slamrun.datasets.file_notes import TARTANAIR_FPS, TARTANAIR_POSES
from slamrun.datasets.protocol import Layout, Placed
from slamrun.datasets.sequence import (
    Sequence,
    folder_sequence,
    number_rows,
    raise_problems,
    require_regular,
    row_count,
    sequence_folder,
)
from slamrun.errors import DatasetError

if TYPE_CHECKING:
    from slamrun.datasets.synth import Synth

WIDTH, HEIGHT = 640, 480
FX = FY = 320.0
CX, CY = 320.0, 240.0
FPS = TARTANAIR_FPS  # frame k is at k / FPS seconds
NED_TO_CAMERA = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])  # M: (forward, right, down) -> (x, y, z)
IMAGES, POSES = "image_left", TARTANAIR_POSES
FRAME_NAME = re.compile(r"(\d{6})_left\.png")


def camera() -> CameraFile:
    return CameraFile(FovCamera(WIDTH, HEIGHT, FX, FY, CX, CY, 0.0), "none", WIDTH, HEIGHT)


def ned_to_camera(traj: Trajectory) -> Trajectory:
    """Each NED pose T as M T M^-1 (tartanair_tools' ned2cam): the camera's and the world's axes from (forward,
    right, down) to (right, down, forward)."""
    m = NED_TO_CAMERA
    rot = m @ quat_to_rotmat(traj.quaternions) @ m.T
    return Trajectory(traj.timestamps, traj.positions @ m.T, rotmat_to_quat(rot))


def open_tartanair(root: str | Path) -> Sequence:
    root = sequence_folder(root)
    images, gt_path = root / IMAGES, root / POSES
    require_regular(root, "TartanAir", [gt_path])
    problems: list[str] = []
    names = _frame_names(images, problems)
    if names:
        frames.check_files(images, names, (WIDTH, HEIGHT), problems, "TartanAir's published camera")
    if names and gt_path.is_file():
        n_poses = row_count(gt_path)
        if n_poses != len(names):
            problems.append(f"{gt_path}: {n_poses} poses but {len(names)} frames; TartanAir's are one per frame")
    raise_problems(root, "TartanAir", problems)
    times = np.arange(len(names)) / FPS

    def groundtruth() -> Trajectory:
        return ned_to_camera(read_poses(gt_path, times))

    return folder_sequence(root, "tartanair", names, times, camera(), images, (), gt_path, groundtruth)


def _frame_names(images: Path, problems: list[str]) -> list[str]:
    """image_left/'s frames, NNNNNN_left.png numbered from 0 without a gap (a pose row per frame number)."""
    if not images.is_dir():
        problems.append(f"{images}: missing; expected the frames NNNNNN_left.png")
        return []
    found = sorted((int(m.group(1)), p.name) for p in images.iterdir() if (m := FRAME_NAME.fullmatch(p.name)))
    if not found:
        problems.append(f"{images}: no frames (expected 000000_left.png ...)")
        return []
    gap = next((i for i, (k, _) in enumerate(found) if k != i), None)
    if gap is not None:
        problems.append(
            f"{images}: frame {gap:06d}_left.png missing (frames are numbered from 0 without a gap, one per row of "
            f"{POSES})"
        )
        return []
    return [name for _, name in found]


def read_poses(path: Path, times: np.ndarray) -> Trajectory:
    """pose_left.txt (NED) at the frames' times: 7 finite numbers a row (tx ty tz qx qy qz qw), a unit quaternion
    within 1e-3 (normalised); every problem named with its line."""
    rows = []
    for n, values in number_rows(path, 7, "7 finite numbers: tx ty tz qx qy qz qw"):
        if abs(np.linalg.norm(values[3:]) - 1.0) > 1e-3:
            raise DatasetError(f"{path}:{n}: the quaternion {values[3:]} is not of unit length")
        rows.append(values)
    if len(rows) != len(times):
        raise DatasetError(f"{path}: {len(rows)} poses but {len(times)} frames; TartanAir's are one per frame")
    data = np.array(rows).reshape(-1, 7)
    quats = data[:, 3:] / np.linalg.norm(data[:, 3:], axis=1, keepdims=True)
    return Trajectory(np.asarray(times, float), data[:, :3], quats)


# ---------------------------------------------------------------------------------------------------- the layout


def recognise(root: Path) -> bool:
    """image_left/ or pose_left.txt."""
    return (root / IMAGES).is_dir() or (root / POSES).exists()


def write_synthetic(tmp: Path, s: Synth) -> Placed:
    """The sequence in TartanAir's layout: image_left/NNNNNN_left.png (colour, the published pinhole) and
    pose_left.txt: the camera's poses in NED axes (camera and world), one row per frame, no times."""
    import cv2

    from slamrun.core.camera import PinholeCamera

    cam = PinholeCamera(WIDTH, HEIGHT, FX, FY, CX, CY)
    images = tmp / IMAGES
    images.mkdir()
    for i, img in s.images(cam):
        cv2.imwrite(str(images / f"{i:06d}_left.png"), cv2.cvtColor(img, cv2.COLOR_GRAY2BGR))
    poses = s.poses_at(s.scene, np.arange(s.frames) / max(s.frames - 1, 1))
    m = NED_TO_CAMERA
    rot = m.T @ poses[:, :3, :3] @ m  # M^-1 T M: the inverse of the reader's carrying
    pos = poses[:, :3, 3] @ m
    quats = rotmat_to_quat(rot)
    (tmp / POSES).write_text(
        "".join(" ".join(f"{v:.9e}" for v in (*pos[i], *quats[i])) + "\n" for i in range(s.frames))
    )
    return []


TARTANAIR_HOWTO = (
    "TartanAir is published per environment and difficulty, every trajectory of one in a zip (ENV/Easy/image_left.zip "
    "holds ENV/Easy/P000/image_left/ ...), with pose_left.txt in each trajectory's folder: fetch them with "
    "tartanair_tools' download_training.py (https://github.com/castacks/tartanair_tools) or from its site, unpack, "
    "and give a spec `layout: tartanair` with `path: <folder>/ENV/Easy` and sequences such as [P000, P001]."
)
LAYOUT = Layout(
    name="tartanair",
    title="TartanAir v1 (image_left, NED poses carried to the camera; frames at 20 Hz)",
    recognise=recognise,
    frame_list=f"{IMAGES}/",
    read=open_tartanair,
    groundtruth_file=POSES,
    synth=write_synthetic,
    fixed_size=(WIDTH, HEIGHT),
    manual_download=TARTANAIR_HOWTO,
    file_note=file_notes.tartanair,
)
