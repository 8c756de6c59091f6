"""A sequence as every dataset reader gives it: frames in order, their timestamps in seconds, the camera and the
ground truth at the frames' times. The view cache builds prepared views from it, whatever the dataset's layout.
"""

from __future__ import annotations

import hashlib
import zipfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from runner.core.camera import CameraFile, FovCamera
from runner.core.trajectory import Trajectory
from runner.errors import DatasetError

IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".pgm", ".bmp")
# The text files' size limit: far above any real sequence's (a times.txt of a million frames is 40 MB), far below
# what would exhaust memory.
MAX_TEXT_BYTES = 256 * 2**20


@dataclass(frozen=True, eq=False)
class Sequence:
    """A validated sequence: frame names in order, their timestamps and exposures, its calibration.

    Frames are members of `zip_path`, or files of `images_dir`. `key_files` are the small files whose content
    defines what a method sees (timestamps, calibration): with the frames' names they key the prepared views.
    """

    root: Path
    frame_names: tuple[str, ...]
    timestamps: np.ndarray
    exposures_ms: np.ndarray | None
    camera: CameraFile
    zip_path: Path | None  # None when frames are files of images_dir
    images_dir: Path | None = None
    layout: str = "tum-mono"
    pcalib: Path | None = None  # photometric calibration (TUM-Mono only)
    vignette: Path | None = None
    camera_txt: Path | None = None  # the dataset's own camera.txt, copied into native views as it is
    groundtruth_path: Path | None = None
    key_files: tuple[Path, ...] = ()
    groundtruth_reader: Callable[[], Trajectory] | None = field(default=None, repr=False)
    notes: tuple[str, ...] = ()  # what a user should know about this sequence's evaluation

    @property
    def name(self) -> str:
        return self.root.name

    @property
    def n_frames(self) -> int:
        return len(self.frame_names)

    @property
    def photometric(self) -> bool:
        """Whether the sequence has a photometric calibration (response and vignette)."""
        return self.pcalib is not None and self.vignette is not None

    @property
    def fov(self) -> bool:
        """Whether the camera is FOV or a plain pinhole, which methods' native calibration files can express;
        other models (radial-tangential, fisheye) reach every method rectified."""
        return isinstance(self.camera.camera, FovCamera)

    def groundtruth(self) -> Trajectory | None:
        """The ground truth at the frames' times (NaN rows where the dataset has no pose), or None."""
        return None if self.groundtruth_reader is None else self.groundtruth_reader()

    def read_bytes(self) -> Iterator[tuple[str, bytes]]:
        """(name, encoded bytes) of every frame, in order."""
        if self.zip_path is not None:
            with zipfile.ZipFile(self.zip_path) as zf:
                for name in self.frame_names:
                    yield name, zf.read(name)
        else:
            assert self.images_dir is not None
            for name in self.frame_names:
                yield name, (self.images_dir / name).read_bytes()

    def frames(self) -> Iterator[np.ndarray]:
        """Decoded 8-bit grayscale frames, in order."""
        for name, data in self.read_bytes():
            img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_GRAYSCALE)
            if img is None:
                raise DatasetError(f"{self.root}: frame {name} cannot be decoded")
            yield img

    def frames_stamp(self) -> str:
        """The frames' container as a key part: the zip's or the folder's name, size and modification time."""
        p = self.zip_path or self.images_dir
        if p is None or not p.exists():
            return "-"
        st = p.stat()
        return f"{p.name}|{st.st_size}|{st.st_mtime_ns}"


def folder_sequence(
    root: Path,
    layout: str,
    names: list[str],
    times: np.ndarray,
    camera: CameraFile,
    images_dir: Path,
    key_files: tuple[Path, ...],
    groundtruth_path: Path,
    groundtruth_reader: Callable[[], Trajectory],
    notes: tuple[str, ...] = (),
) -> Sequence:
    """A sequence whose frames are files of a folder, without photometric calibration (every layout but
    TUM-Mono); its ground truth where the file exists."""
    has_gt = groundtruth_path.is_file()
    return Sequence(
        root,
        tuple(names),
        times,
        None,
        camera,
        None,
        images_dir=images_dir,
        layout=layout,
        groundtruth_path=groundtruth_path if has_gt else None,
        key_files=key_files,
        groundtruth_reader=groundtruth_reader if has_gt else None,
        notes=notes,
    )


def check_regular(paths: list[Path], text_files: set[Path]) -> list[str]:
    """The files among `paths` that exist but cannot be read to an end: not regular files (a device such as
    /dev/zero, a pipe, a folder) or text files beyond MAX_TEXT_BYTES."""
    problems = []
    for p in paths:
        if not (p.exists() or p.is_symlink()):
            continue
        if not p.is_file():
            problems.append(
                f"{p}: not a regular file (a device, pipe, folder or broken link); expected the file itself"
            )
        elif p in text_files and p.stat().st_size > MAX_TEXT_BYTES:
            problems.append(f"{p}: {p.stat().st_size / 2**20:.0f} MB, more than a sequence's {p.name} can be")
    return problems


def read_text(path: Path) -> str:
    """A small text file as text, or DatasetError naming it (binary, not UTF-8)."""
    try:
        return path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as exc:
        raise DatasetError(f"{path}: not a text file (byte {exc.start} is not UTF-8)") from None


def check_first_frame(seq_root: Path, images_dir: Path, name: str, size: tuple[int, int], problems: list[str]) -> None:
    """The first frame decodes and has the calibration's size."""
    img = cv2.imread(str(images_dir / name), cv2.IMREAD_UNCHANGED)
    if img is None:
        problems.append(f"{images_dir / name}: cannot be decoded as an image")
        return
    h, w = img.shape[:2]
    if (w, h) != size:
        problems.append(f"{images_dir / name}: {w}x{h}, but the calibration of {seq_root} is for {size[0]}x{size[1]}")


def folder_identity(key_files: list[Path], images_dir: Path, names: list[str]) -> str:
    """A digest of a sequence whose frames are files: the key files in full, the frames by name, size and first
    4 KiB (independent of paths and dates, so a moved or copied dataset keeps its runs)."""
    h = hashlib.sha256()
    for p in key_files:
        h.update(p.name.encode() + b"\0" + (p.read_bytes() if p.is_file() else b"-") + b"\0")
    for name in names:
        p = images_dir / name
        try:
            with open(p, "rb") as f:
                head = f.read(4096)
            h.update(f"{name}|{p.stat().st_size}|".encode() + hashlib.sha256(head).digest())
        except OSError:
            h.update(f"{name}|missing".encode())
    return h.hexdigest()[:10]


def interpolate_poses(gt: Trajectory, times: np.ndarray, max_gap_s: float) -> Trajectory:
    """The poses of `gt` at `times`: positions linearly, rotations by slerp between the two samples around each
    time when both are within `max_gap_s` of it; NaN rows elsewhere (before, after or inside a gap of `gt`)."""
    from scipy.spatial.transform import Rotation, Slerp

    n = len(times)
    pos = np.full((n, 3), np.nan)
    quat = np.full((n, 4), np.nan)
    t = gt.timestamps
    if len(t) >= 2:
        j = np.clip(np.searchsorted(t, times), 1, len(t) - 1)
        t0, t1 = t[j - 1], t[j]
        exact0, exact1 = np.abs(times - t0) < 1e-9, np.abs(times - t1) < 1e-9
        inside = (times >= t0) & (times <= t1) & (times - t0 <= max_gap_s) & (t1 - times <= max_gap_s)
        ok = inside | exact0 | exact1
        w = np.where(t1 > t0, (times - t0) / np.where(t1 > t0, t1 - t0, 1.0), 0.0)
        w = np.clip(w, 0.0, 1.0)
        pos_i = gt.positions[j - 1] * (1 - w)[:, None] + gt.positions[j] * w[:, None]
        slerp = Slerp(t, Rotation.from_quat(gt.quaternions))
        q_i = slerp(np.clip(times, t[0], t[-1])).as_quat()
        pos[ok], quat[ok] = pos_i[ok], q_i[ok]
    elif len(t) == 1:
        hit = np.abs(times - t[0]) < 1e-9
        pos[hit], quat[hit] = gt.positions[0], gt.quaternions[0]
    return Trajectory(np.asarray(times, float), pos, quat)


def nearest_poses(gt: Trajectory, times: np.ndarray, tolerance_s: float) -> Trajectory:
    """The pose of `gt` nearest in time to each of `times` within `tolerance_s` (TUM RGB-D's association), put
    at that time; NaN rows where none is that close."""
    n = len(times)
    pos = np.full((n, 3), np.nan)
    quat = np.full((n, 4), np.nan)
    t = gt.timestamps
    if len(t):
        j = np.clip(np.searchsorted(t, times), 1, max(len(t) - 1, 1))
        lo = np.clip(j - 1, 0, len(t) - 1)
        hi = np.clip(j, 0, len(t) - 1)
        nearest = np.where(np.abs(t[lo] - times) <= np.abs(t[hi] - times), lo, hi)
        ok = np.abs(t[nearest] - times) <= tolerance_s
        pos[ok], quat[ok] = gt.positions[nearest[ok]], gt.quaternions[nearest[ok]]
    return Trajectory(np.asarray(times, float), pos, quat)


def transform_poses(traj: Trajectory, right: np.ndarray) -> Trajectory:
    """Each pose T_WB of `traj` times the fixed 4x4 `right` (e.g. T_BC: body poses to camera poses)."""
    from runner.core.trajectory import quat_to_rotmat, rotmat_to_quat

    ok = np.isfinite(traj.positions).all(axis=1) & np.isfinite(traj.quaternions).all(axis=1)
    new_pos = np.full_like(traj.positions, np.nan)
    quats = np.full_like(traj.quaternions, np.nan)
    rot = quat_to_rotmat(traj.quaternions[ok])
    new_pos[ok] = np.einsum("nij,j->ni", rot, right[:3, 3]) + traj.positions[ok]
    quats[ok] = rotmat_to_quat(rot @ right[:3, :3])
    return Trajectory(traj.timestamps, new_pos, quats)
