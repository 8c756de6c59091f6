"""`slamrun new-dataset NAME`: a dataset layout of one's own (a lab's recordings), outside slamrun's repository.

Writes a Python package that registers the layout through the `slamrun.datasets` entry point (a
slamrun.datasets.protocol.Layout value), and a test. As written, the layout reads a plain one that works at once:
`frames/` with `frames.csv` (`time_s,file`), `intrinsics.txt` (a pinhole camera) and `poses.csv` (the ground truth,
camera-to-world in the camera's axes), and writes it synthetically (`slamrun synth OUT --layout NAME`); the lines a
person changes for their own files are marked `FILL IN`.
"""

from __future__ import annotations

import re
from pathlib import Path

from slamrun.errors import SlamRunError
from slamrun.images.scaffold import MAX_NAME, destination_problem, pyproject, write_files

LAYOUT = '''"""__NAME__: a dataset layout for slamrun (the contract of slamrun/datasets/protocol.py in slamrun's
repository).

A sequence folder holds (FILL IN: your layout's files, where they differ):
  frames/          the frames (PNG or JPEG)
  frames.csv       one row per frame, in order: `time_s,file` (lines starting with # are skipped)
  intrinsics.txt   one line: `fx fy cx cy width height` (a pinhole camera; the frames undistorted)
  poses.csv        the ground truth (optional): `time_s,tx,ty,tz,qx,qy,qz,qw` rows, camera-to-world, in the
                   camera's axes (x right, y down, z forward), at any rate (interpolated at the frames' times)
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from slamrun.datasets import (
    IMAGE_SUFFIXES,
    CameraFile,
    DatasetError,
    FovCamera,
    Layout,
    PinholeCamera,
    Sequence,
    Trajectory,
    camera_problem,
    check_regular,
    folder_sequence,
    frames,
    interpolate_poses,
    read_text,
    rotmat_to_quat,
    time_problem,
)

FRAMES, LIST, INTRINSICS, POSES = "frames", "frames.csv", "intrinsics.txt", "poses.csv"  # FILL IN: your names
MAX_GAP_S = 0.05  # FILL IN: ground truth is interpolated between samples at most this far from a frame


def recognise(root: Path) -> bool:
    """Whether a folder is a sequence of this layout, from its files (slamrun's own layouts are tried first)."""
    return (root / LIST).exists() and (root / INTRINSICS).exists()  # FILL IN: what marks your folders


def read(root: Path) -> Sequence:
    """The sequence, validated: one DatasetError lists every problem, each with its file (and line)."""
    listing, intrinsics, gt_path = root / LIST, root / INTRINSICS, root / POSES
    problems = check_regular([listing, intrinsics, gt_path], {listing, intrinsics, gt_path})
    if problems:
        raise DatasetError(f"{root}: invalid __NAME__ sequence:\\n  " + "\\n  ".join(problems))
    camera = _read_intrinsics(intrinsics, problems) if intrinsics.is_file() else None
    if camera is None and not intrinsics.is_file():
        problems.append(f"{intrinsics}: missing; expected 'fx fy cx cy width height'")
    names, times = _read_list(listing, problems) if listing.is_file() else ([], None)
    if not listing.is_file():
        problems.append(f"{listing}: missing; expected 'time_s,file' rows")
    if names and camera is not None:
        size = (camera.camera.width, camera.camera.height)
        frames.check_files(root / FRAMES, names, size, problems, INTRINSICS)
    if problems:
        raise DatasetError(f"{root}: invalid __NAME__ sequence:\\n  " + "\\n  ".join(problems))
    assert camera is not None and times is not None

    def groundtruth() -> Trajectory:
        return interpolate_poses(read_poses(gt_path), times, MAX_GAP_S)

    return folder_sequence(
        root, "__NAME__", names, times, camera, root / FRAMES, (listing, intrinsics), gt_path, groundtruth
    )


def _read_intrinsics(path: Path, problems: list[str]) -> CameraFile | None:
    try:
        fx, fy, cx, cy, w, h = (float(v) for v in read_text(path).split())
    except ValueError:
        problems.append(f"{path}: expected one line of 6 numbers: fx fy cx cy width height")
        return None
    camera = CameraFile(FovCamera(int(w), int(h), fx, fy, cx, cy, 0.0), "none", int(w), int(h))
    if problem := camera_problem(path, camera):
        problems.append(problem)
        return None
    return camera


def _read_list(path: Path, problems: list[str]) -> tuple[list[str], np.ndarray | None]:
    names, stamps = [], []
    for n, line in enumerate(read_text(path).splitlines(), start=1):
        if not line.strip() or line.startswith("#"):
            continue
        cells = [c.strip() for c in line.split(",")]
        try:
            stamps.append(float(cells[0]))
        except ValueError:
            problems.append(f"{path}:{n}: {cells[0][:60]!r} is not a time in seconds")
            return [], None
        if len(cells) != 2 or not cells[1].lower().endswith(IMAGE_SUFFIXES) or "/" in cells[1]:
            problems.append(f"{path}:{n}: {line.strip()[:80]!r}; expected 'time_s,file' (a frame of {FRAMES}/)")
            return [], None
        if problem := time_problem(path, n, cells[0][:60], stamps[-1]):
            problems.append(problem)
            return [], None
        names.append(cells[1])
    t = np.array(stamps)
    if not names:
        problems.append(f"{path}: no frame listed")
    elif np.any(np.diff(t) <= 0):
        problems.append(f"{path}: times not strictly increasing")
    else:
        return names, t
    return [], None


def read_poses(path: Path) -> Trajectory:
    """poses.csv: camera-to-world poses in the camera's axes. FILL IN: carry yours there if they are in another
    frame (a body, NED, a y-up camera), as slamrun's EuRoC, TartanAir and ICL-NUIM readers do."""
    rows = []
    for n, line in enumerate(read_text(path).splitlines(), start=1):
        if not line.strip() or line.startswith("#"):
            continue
        try:
            values = [float(v) for v in line.split(",")]
        except ValueError:
            raise DatasetError(f"{path}:{n}: not numbers: {line.strip()[:60]!r}") from None
        if len(values) != 8 or not np.isfinite(values).all():
            raise DatasetError(f"{path}:{n}: expected 8 finite numbers: time_s,tx,ty,tz,qx,qy,qz,qw")
        rows.append(values)
    data = np.array(rows).reshape(-1, 8)
    if np.any(np.diff(data[:, 0]) <= 0):
        raise DatasetError(f"{path}: times not strictly increasing")
    quats = data[:, 4:] / np.linalg.norm(data[:, 4:], axis=1, keepdims=True)
    return Trajectory(data[:, 0], data[:, 1:4], quats)


def write_synthetic(tmp: Path, s) -> list:
    """A synthetic sequence in this layout (`slamrun synth OUT --layout __NAME__`): slamrun's rendered room seen by a
    pinhole camera, 30 Hz, and its exact poses. FILL IN: your layout's quirks (its names, rates, frames)."""
    import cv2

    w, h = s.size
    cam = PinholeCamera(w, h, 0.6 * w, 0.6 * w, w / 2 - 0.5, h / 2 - 0.5)
    (tmp / FRAMES).mkdir()
    t = 100.0 + np.arange(s.frames) / 30.0
    for i, img in s.images(cam):
        cv2.imwrite(str(tmp / FRAMES / f"{i:06d}.png"), img)
    (tmp / LIST).write_text("# time_s,file\\n" + "".join(f"{t[i]:.9f},{i:06d}.png\\n" for i in range(s.frames)))
    (tmp / INTRINSICS).write_text(f"{cam.fx} {cam.fy} {cam.cx} {cam.cy} {w} {h}\\n")
    poses = s.poses_at(s.scene, np.arange(s.frames) / max(s.frames - 1, 1))
    q = rotmat_to_quat(poses[:, :3, :3])
    (tmp / POSES).write_text(
        "".join(",".join(f"{v:.9f}" for v in (t[i], *poses[i, :3, 3], *q[i])) + "\\n" for i in range(s.frames))
    )
    return []


LAYOUT = Layout(
    name="__NAME__",
    title="__NAME__ (FILL IN: the dataset as people name it)",
    recognise=recognise,
    frame_list=LIST,
    read=read,
    groundtruth_file=POSES,
    default_metrics=("ate", "rpe"),
    synth=write_synthetic,
)
'''

TEST = '''"""__NAME__'s layout: its reader on its own synthetic sequence, and a bad file named with its line."""

from pathlib import Path

import numpy as np
import pytest

from slamrun.datasets import DatasetError, Synth
from slamrun_dataset___MODULE__.layout import LAYOUT


def synthetic(root: Path) -> tuple[Path, Synth]:
    s = Synth(40, 1, (160, 120), "indoor", "seq")
    root.mkdir()
    LAYOUT.synth(root, s)
    return root, s


def test_the_reader_gives_the_frames_times_and_poses_the_writer_wrote(tmp_path):
    root, s = synthetic(tmp_path / "seq")
    assert LAYOUT.recognise(root)
    seq = LAYOUT.read(root)
    assert seq.n_frames == 40 and np.all(np.diff(seq.timestamps) > 0)
    truth = s.poses_at(s.scene, np.arange(40) / 39)
    assert np.allclose(seq.groundtruth().positions, truth[:, :3, 3], atol=1e-6)


def test_a_bad_row_is_named_with_its_file_and_line(tmp_path):
    root, _ = synthetic(tmp_path / "seq")
    listing = root / "frames.csv"  # FILL IN: your frame list
    lines = listing.read_text().splitlines()
    lines[3] = "soon," + lines[3].split(",")[1]
    listing.write_text("\\n".join(lines) + "\\n")
    with pytest.raises(DatasetError, match="frames.csv:4"):
        LAYOUT.read(root)
'''


def new_dataset(name: str, dest: Path) -> list[Path]:
    """Write the package of layout `name` into `dest` (which must not exist or be empty); returns the files."""
    if not re.fullmatch(r"[a-z][a-z0-9]*(-[a-z0-9]+)*", name):
        raise SlamRunError(f"{name!r}: a layout name is lower-case letters and digits, parts joined by - (my-lab)")
    from slamrun.datasets.layouts import LAYOUTS

    if name in LAYOUTS:
        raise SlamRunError(f"{name!r} is a layout slamrun reads already; choose another name")
    if len(name) > MAX_NAME:
        raise SlamRunError(f"{name[:20]}...: a layout name of {len(name)} characters; at most {MAX_NAME}")
    if problem := destination_problem(dest):
        raise SlamRunError(problem)
    module = name.replace("-", "_")
    package = dest / f"slamrun_dataset_{module}"
    files = {
        dest / "pyproject.toml": pyproject(
            "slamrun-dataset-__NAME__",
            "The __NAME__ dataset layout for slamrun",
            "slamrun.datasets",
            '__NAME__ = "slamrun_dataset___MODULE__.layout:LAYOUT"',
            "slamrun_dataset___MODULE__",
        ),
        package / "__init__.py": "",
        package / "layout.py": LAYOUT,
        dest / "tests" / f"test_{module}.py": TEST,
    }
    return write_files(
        {path: text.replace("__NAME__", name).replace("__MODULE__", module) for path, text in files.items()}
    )
