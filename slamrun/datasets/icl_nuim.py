"""ICL-NUIM, its TUM RGB-D-compatible release (`living_room_traj0_frei_png/` ... `traj3_frei_png/`: living room and
office kt0-kt3): `rgb/<k>.png` (640x480 colour), `depth/`, `associations.txt` (`k depth/k.png k rgb/k.png` rows: frame
numbers, not times) and the ground truth `livingRoom<k>.gt.freiburg` or `traj<k>.gt.freiburg` (TUM rows, frame
numbers for times; the release has no pose for frame 0). The camera is the published one: fx 481.20, fy -480.00,
cx 319.50, cy 239.50, no distortion.

Times: the release numbers its frames; slamrun takes frame k at k / 30 s (the rate the sequences were rendered at)
for the frames and the ground truth alike, so they associate exactly, frame by frame.

The negative fy: the ground truth's camera has its y axis up (x right, z forward), so the images are y-flipped with
respect to the poses, and their world is a mirror image of a right-handed one. slamrun gives methods the images as
published with fy +480.00 (an ordinary y-down pinhole camera, which every method takes) and carries the ground truth
into that camera: each pose T_wc becomes S T_wc S with S = diag(1, -1, 1) (positions (x, -y, z), rotations S R S,
proper rotations still). The same mirror on both trajectories leaves ATE and RPE unchanged, so figures are those of
the release's own frame; a method's estimate, made with fy +480, is compared with poses of its own camera.
"""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from slamrun.core.camera import CameraFile, FovCamera
from slamrun.core.metrics import poses_at
from slamrun.core.trajectory import Trajectory, quat_to_rotmat, read_tum, rotmat_to_quat
from slamrun.datasets import file_notes, frames
from slamrun.datasets.file_notes import ICL_NUIM_FPS
from slamrun.datasets.protocol import Download, Layout, Placed
from slamrun.datasets.sequence import (
    FrameRow,
    Sequence,
    check_regular,
    folder_sequence,
    raise_problems,
    read_frame_list,
    read_groundtruth,
    sequence_folder,
)

if TYPE_CHECKING:
    from slamrun.datasets.synth import Synth

WIDTH, HEIGHT = 640, 480
FX, FY, CX, CY = 481.20, -480.00, 319.50, 239.50  # as published; fy's sign is the y-up camera of the poses
FPS = ICL_NUIM_FPS  # frame k is at k / FPS seconds
MIRROR = np.diag([1.0, -1.0, 1.0])  # S: the y-up camera (and its mirrored world) to a y-down one
ASSOCIATIONS = "associations.txt"


def camera() -> CameraFile:
    """The published camera as methods take it: fy positive (images as published; the ground truth mirrored)."""
    return CameraFile(FovCamera(WIDTH, HEIGHT, FX, abs(FY), CX, CY, 0.0), "none", WIDTH, HEIGHT)


def mirror_y(traj: Trajectory) -> Trajectory:
    """Each pose T_wc as S T_wc S, S = diag(1, -1, 1): poses of a y-up camera in its (mirrored) world carried to a
    y-down camera in a right-handed one; NaN rows stay NaN. Its own inverse."""
    ok = np.isfinite(traj.positions).all(axis=1) & np.isfinite(traj.quaternions).all(axis=1)
    pos = np.full_like(traj.positions, np.nan)
    quat = np.full_like(traj.quaternions, np.nan)
    pos[ok] = traj.positions[ok] @ MIRROR
    quat[ok] = rotmat_to_quat(MIRROR @ quat_to_rotmat(traj.quaternions[ok]) @ MIRROR)
    return Trajectory(traj.timestamps, pos, quat)


def groundtruth_files(root: Path) -> list[Path]:
    return sorted(root.glob("*.gt.freiburg"))


def open_icl_nuim(root: str | Path) -> Sequence:
    root = sequence_folder(root)
    listing = root / ASSOCIATIONS
    gts = groundtruth_files(root)
    problems = check_regular([listing, *gts], {listing, *gts})
    if len(gts) > 1:
        problems.append(f"{root}: {len(gts)} *.gt.freiburg files ({', '.join(p.name for p in gts)}); expected one")
    raise_problems(root, "ICL-NUIM", problems)
    names, times = [], None
    if not listing.is_file():
        problems.append(f"{listing}: missing; expected 'k depth/k.png k rgb/k.png' rows")
    else:
        names, times = _read_associations(listing, problems)
    frames.check_listed(root, names, ASSOCIATIONS, (WIDTH, HEIGHT), problems, "ICL-NUIM's published camera")
    raise_problems(root, "ICL-NUIM", problems)
    assert times is not None
    gt_path = gts[0] if gts else root / "groundtruth.gt.freiburg"

    def groundtruth() -> Trajectory:
        gt = read_groundtruth(gt_path, read_tum)
        in_seconds = Trajectory(gt.timestamps / FPS, gt.positions, gt.quaternions)
        return mirror_y(poses_at(in_seconds, times, 0.25 / FPS))

    return folder_sequence(root, "icl-nuim", names, times, camera(), root, (listing,), gt_path, groundtruth)


def _read_associations(path: Path, problems: list[str]) -> tuple[list[str], np.ndarray | None]:
    """associations.txt: the rgb/ frame of each row and its number, as a time in seconds (k / FPS)."""
    return read_frame_list(path, problems, _associated_frame, "frame numbers")


def _associated_frame(cells: list[str], line: str) -> FrameRow | str:
    pairs = list(zip(cells[0::2], cells[1::2], strict=False))
    rgb = [(t, name) for t, name in pairs if name.startswith("rgb/")]
    if len(cells) != 4 or len(rgb) != 1:
        return f"{line.strip()[:80]!r}; expected 'k depth/k.png k rgb/k.png'"
    token, name = rgb[0]
    try:
        return token, float(token) / FPS, name
    except ValueError:
        return f"{token[:60]!r} is not a frame number"


# ---------------------------------------------------------------------------------------------------- the layout


def recognise(root: Path) -> bool:
    """A *.gt.freiburg, or associations.txt without TUM RGB-D's rgb.txt."""
    if (root / ASSOCIATIONS).exists() and not (root / "rgb.txt").exists():
        return True
    return bool(groundtruth_files(root))


def _groundtruth_name(name: str) -> str:
    """The release's name of a sequence's ground truth: livingRoom<k> for the living room, traj<k> for the office."""
    found = re.search(r"traj(\d)", name)
    k = found.group(1) if found else "0"
    return f"livingRoom{k}.gt.freiburg" if name.startswith("living_room") else f"traj{k}.gt.freiburg"


def write_synthetic(tmp: Path, s: Synth) -> Placed:
    """The sequence in ICL-NUIM's TUM-compatible layout: rgb/<k>.png (colour, 640x480, rendered by a y-down camera
    of the published |fy|), associations.txt with frame numbers, and the ground truth as the release has it: frame
    numbers for times, no pose for frame 0, and the poses of the y-up camera in the mirrored world (S T S), so that
    the published fy -480 projects the scene as the images show it. No depth images (slamrun is monocular)."""
    import cv2

    from slamrun.core.camera import PinholeCamera

    cam = PinholeCamera(WIDTH, HEIGHT, FX, abs(FY), CX, CY)
    rgb = tmp / "rgb"
    rgb.mkdir()
    for i, img in s.images(cam):
        cv2.imwrite(str(rgb / f"{i}.png"), cv2.cvtColor(img, cv2.COLOR_GRAY2BGR))
    (tmp / ASSOCIATIONS).write_text("".join(f"{i} depth/{i}.png {i} rgb/{i}.png\n" for i in range(s.frames)))
    poses = s.poses_at(s.scene, np.arange(s.frames) / max(s.frames - 1, 1))
    mirror = np.diag([1.0, -1.0, 1.0, 1.0])
    released = mirror @ poses @ mirror  # the y-up camera in the mirrored world
    quats = rotmat_to_quat(released[:, :3, :3])
    rows = [
        f"{i} " + " ".join(f"{v:.9g}" for v in (*released[i, :3, 3], *quats[i])) for i in range(1, s.frames)
    ]  # the release has no pose for frame 0
    (tmp / _groundtruth_name(s.name)).write_text("\n".join(rows) + "\n")
    return []


URL = os.environ.get("SLAMRUN_ICL_NUIM_URL", "https://www.doc.ic.ac.uk/~ahanda")
SCENES = {"lr": "living_room_traj{k}_frei_png", "of": "traj{k}_frei_png"}  # living room, office


def _archive(name: str, base: str) -> tuple[str, str] | None:
    """A sequence by the release's folder name (living_room_traj0_frei_png, traj0_frei_png) or as papers name it
    (lr_kt0, of_kt0) → its folder and the site's <folder>.tar.gz."""
    short = re.fullmatch(r"(lr|of)[_-]?kt([0-3])", name)
    if short:
        folder = SCENES[short.group(1)].format(k=short.group(2))
    elif re.fullmatch(r"(living_room_)?traj[0-3]_frei_png", name):
        folder = name
    else:
        return None
    return folder, f"{base}/{folder}.tar.gz"


LAYOUT = Layout(
    name="icl-nuim",
    title="ICL-NUIM (TUM RGB-D-compatible release; the y-up poses mirrored to the camera methods see)",
    recognise=recognise,
    frame_list=ASSOCIATIONS,
    read=open_icl_nuim,
    groundtruth_file="livingRoom<k>.gt.freiburg or traj<k>.gt.freiburg",
    synth=write_synthetic,
    fixed_size=(WIDTH, HEIGHT),
    download=Download(
        URL,
        _archive,
        "lr_kt0-lr_kt3 and of_kt0-of_kt3 (living room, office), or the release's folder names such as "
        "living_room_traj0_frei_png and traj0_frei_png",
        default=tuple(SCENES[scene].format(k=k) for scene in SCENES for k in range(4)),  # the study's eight
    ),
    file_note=file_notes.icl_nuim,
)
