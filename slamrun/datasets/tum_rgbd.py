"""TUM RGB-D sequences (`rgbd_dataset_freiburgN_...`): `rgb.txt` (`timestamp rgb/<timestamp>.png` rows after `#`
comments), the colour frames in `rgb/`, and `groundtruth.txt` (TUM format, motion capture at 100 Hz). The camera is
one of the three the benchmark publishes, chosen by `freiburg1`, `freiburg2` or `freiburg3` in the folder's name.
Ground truth is associated with the frames as TUM's tools do: the nearest pose within 0.02 s. Written synthetically
with the named camera, colour frames and a 100 Hz ground truth on its own clock; downloaded as the site's .tgz.
"""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from slamrun.core.camera import CameraFile, FovCamera, PinholeCamera, RadTanCamera
from slamrun.core.metrics import poses_at
from slamrun.core.trajectory import Trajectory, read_tum
from slamrun.datasets import frames
from slamrun.datasets.protocol import Download, Layout, Placed
from slamrun.datasets.sequence import (
    FrameRow,
    Sequence,
    folder_sequence,
    raise_problems,
    read_frame_list,
    read_groundtruth,
    require_regular,
    sequence_folder,
)
from slamrun.errors import DatasetError

if TYPE_CHECKING:
    from slamrun.datasets.synth import Synth

ASSOCIATION_S = 0.02
WIDTH, HEIGHT = 640, 480
# The benchmark's published intrinsics (fx fy cx cy) and OpenCV distortion (k1 k2 p1 p2 k3) of the colour camera
CAMERAS = {
    "freiburg1": ((517.3, 516.5, 318.6, 255.3), (0.2624, -0.9531, -0.0054, 0.0026, 1.1633)),
    "freiburg2": ((520.9, 521.0, 325.1, 249.7), (0.2312, -0.7849, -0.0033, -0.0001, 0.9172)),
    "freiburg3": ((535.4, 539.2, 320.1, 247.6), (0.0, 0.0, 0.0, 0.0, 0.0)),
}


def camera_for(root: Path) -> CameraFile:
    """The published camera of the sequence, by `freiburgN` in its folder's name."""
    found = re.search(r"freiburg[123]", root.name)
    if found is None:
        raise DatasetError(
            f"{root}: unknown TUM RGB-D camera; the folder's name must hold freiburg1, freiburg2 or freiburg3 "
            "(as the benchmark's rgbd_dataset_freiburgN_... folders do) to choose its published calibration"
        )
    (fx, fy, cx, cy), k = CAMERAS[found.group(0)]
    if not any(k):
        return CameraFile(FovCamera(WIDTH, HEIGHT, fx, fy, cx, cy, 0.0), "none", WIDTH, HEIGHT)
    return CameraFile(RadTanCamera(PinholeCamera(WIDTH, HEIGHT, fx, fy, cx, cy), *k), "crop", WIDTH, HEIGHT)


def open_tum_rgbd(root: str | Path) -> Sequence:
    root = sequence_folder(root)
    listing, gt_path = root / "rgb.txt", root / "groundtruth.txt"
    require_regular(root, "TUM RGB-D", [listing, gt_path])
    problems: list[str] = []
    camera = None
    try:
        camera = camera_for(root)
    except DatasetError as exc:
        problems.append(str(exc))
    names, times = [], None
    if not listing.is_file():
        problems.append(f"{listing}: missing; expected 'timestamp rgb/<file>.png' rows")
    else:
        names, times = _read_listing(listing, problems)
    frames.check_listed(root, names, "rgb.txt", (WIDTH, HEIGHT), problems, "the TUM RGB-D camera")
    raise_problems(root, "TUM RGB-D", problems)
    assert camera is not None and times is not None

    def groundtruth() -> Trajectory:
        # evo's association: a repeated time's rows kept
        return poses_at(read_groundtruth(gt_path, read_tum), times, ASSOCIATION_S)

    return folder_sequence(root, "tum-rgbd", names, times, camera, root, (listing,), gt_path, groundtruth)


def _read_listing(path: Path, problems: list[str]) -> tuple[list[str], np.ndarray | None]:
    """rgb.txt: `timestamp rgb/<file>.png` rows."""
    return read_frame_list(path, problems, _listed_frame, "times")


def _listed_frame(cells: list[str], line: str) -> FrameRow | str:
    if len(cells) != 2:
        return f"{len(cells)} values; expected 'timestamp rgb/<file>.png'"
    try:
        return cells[0], float(cells[0]), cells[1]
    except ValueError:
        return f"{cells[0][:60]!r} is not a time in seconds"


# ---------------------------------------------------------------------------------------------------- the layout


def recognise(root: Path) -> bool:
    """rgb.txt (and no ICL-NUIM *.gt.freiburg: a TUM-compatible ICL-NUIM sequence given an rgb.txt is ICL-NUIM)."""
    return (root / "rgb.txt").exists() and not any(root.glob("*.gt.freiburg"))


def synth_name_problem(name: str) -> str | None:
    """A synthetic TUM RGB-D sequence takes the published camera its name names."""
    if re.search(r"freiburg[123]", name):
        return None
    return (
        f"{name!r}: a synthetic TUM RGB-D sequence takes the camera of its name: name it with freiburg1, freiburg2 "
        "or freiburg3 (e.g. rgbd_dataset_freiburg1_room)"
    )


def write_synthetic(tmp: Path, s: Synth) -> Placed:
    """The sequence in TUM RGB-D's layout: colour PNGs named by their (slightly irregular) 30 Hz times, rgb.txt,
    and the motion capture's poses at 100 Hz on its own clock ticks, 4 decimals as the benchmark writes them."""
    import cv2

    from slamrun.datasets.synth import loop_fraction, tum_rows

    cam = camera_for(Path(s.name)).camera
    rgb = tmp / "rgb"
    rgb.mkdir()
    t = 1305031102.175304 + np.arange(s.frames) / 30.0 + (np.arange(s.frames) % 4) * 0.0011
    names = [f"rgb/{v:.6f}.png" for v in t]
    for i, img in s.images(cam):
        cv2.imwrite(str(tmp / names[i]), cv2.cvtColor(img, cv2.COLOR_GRAY2BGR))
    (tmp / "rgb.txt").write_text(
        f"# color images\n# file: '{s.name}.bag'\n# timestamp filename\n"
        + "".join(f"{v:.6f} {n}\n" for v, n in zip(t, names, strict=True))
    )
    t_gt = np.arange(t[0] - 0.05 + 0.0043, t[-1] + 0.05, 0.01)  # motion capture at 100 Hz, its own clock ticks
    frac = loop_fraction(t_gt, t)
    rows = tum_rows(t_gt, s.poses_at(s.scene, frac))
    (tmp / "groundtruth.txt").write_text(
        f"# ground truth trajectory\n# file: '{s.name}.bag'\n# timestamp tx ty tz qx qy qz qw\n"
        + "".join(f"{r[0]:.4f} " + " ".join(f"{v:.4f}" for v in r[1:]) + "\n" for r in rows)
    )
    return []


URL = os.environ.get("SLAMRUN_TUM_RGBD_URL", "https://vision.in.tum.de/rgbd/dataset")


def _archive(name: str, base: str) -> tuple[str, str] | None:
    full = name if name.startswith("rgbd_dataset_") else f"rgbd_dataset_{name}"
    found = re.fullmatch(r"rgbd_dataset_(freiburg[123])_[a-z0-9_]+", full)
    return None if found is None else (full, f"{base}/{found.group(1)}/{full}.tgz")


LAYOUT = Layout(
    name="tum-rgbd",
    title="TUM RGB-D (the colour camera; motion-capture ground truth)",
    recognise=recognise,
    frame_list="rgb.txt",
    read=open_tum_rgbd,
    groundtruth_file="groundtruth.txt",
    synth=write_synthetic,
    synth_name_problem=synth_name_problem,
    fixed_size=(WIDTH, HEIGHT),
    download=Download(URL, _archive, "rgbd_dataset_freiburg1_xyz, freiburg2_desk, ... (the benchmark's folder names)"),
)
