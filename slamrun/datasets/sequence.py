"""A sequence as every dataset reader gives it: frames in order, their timestamps in seconds, the camera and the
ground truth at the frames' times. The view cache builds prepared views from it, whatever the dataset's layout.
"""

from __future__ import annotations

import math
import zipfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from slamrun.core.camera import CameraFile, FovCamera, rectification_problem
from slamrun.core.inputs import read_bounded, read_text_bounded, regular_file_problem
from slamrun.core.nearest import nearest
from slamrun.core.trajectory import Trajectory
from slamrun.datasets.frames import GRAYSCALE, decode, read_frame, read_head, read_member
from slamrun.errors import DatasetError, SlamRunError, TrajectoryFormatError

IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".pgm", ".bmp")
# The text files' size limit: far above any real sequence's (a times.txt of a million frames is 40 MB), far below
# what would exhaust memory.
MAX_TEXT_BYTES = 256 * 2**20
# Frame times are seconds (Unix time, or from the sequence's start): finite, and within 1e10 s (the year 2286).
MAX_TIME_S = 1e10
# Ground-truth positions: finite (NaN only where a file marks a frame without a pose) and within 1000 km of the
# origin; a trajectory of a car, a drone or a hand-held camera stays far inside.
MAX_POSITION_M = 1e6


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

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) of every frame: the calibration's input size."""
        return (self.camera.camera.width, self.camera.camera.height)

    def groundtruth(self) -> Trajectory | None:
        """The ground truth at the frames' times (NaN rows where the dataset has no pose), or None; DatasetError
        naming the file where its poses are not plausible (`check_positions`)."""
        if self.groundtruth_reader is None:
            return None
        gt = self.groundtruth_reader()
        assert self.groundtruth_path is not None
        check_positions(gt, self.groundtruth_path)
        if len(gt) and not np.isfinite(gt.positions).all(axis=1).any():  # the dataset's fault, never a method's
            t = self.timestamps
            raise DatasetError(
                f"{self.groundtruth_path}: no ground-truth pose at any of the {len(t)} frames' times "
                f"({float(t[0]):.6f}..{float(t[-1]):.6f} s): the ground truth of another sequence, or another time "
                "base?"
            )
        return gt

    def where(self, name: str) -> str:
        """A frame as messages name it: its file, or its zip and member."""
        if self.zip_path is not None:
            return f"{self.zip_path}: member {name}"
        assert self.images_dir is not None
        return str(self.images_dir / name)

    def read_bytes(self) -> Iterator[tuple[str, bytes]]:
        """(name, encoded bytes) of every frame, in order; each read with the bounds of slamrun.datasets.frames
        (DatasetError naming the frame otherwise)."""
        if self.zip_path is not None:
            try:
                with zipfile.ZipFile(self.zip_path) as zf:
                    for name in self.frame_names:
                        yield name, read_member(zf, self.zip_path, name)
            except (zipfile.BadZipFile, OSError) as exc:
                raise DatasetError(f"{self.zip_path}: not a readable zip ({exc}); re-download the sequence") from None
        else:
            assert self.images_dir is not None
            for name in self.frame_names:
                yield name, read_frame(self.images_dir / name)

    def decode(self, name: str, data: bytes, flags: int = GRAYSCALE) -> np.ndarray:
        """Frame `name` decoded; DatasetError naming it when it does not decode or is not the calibration's size."""
        return decode(data, self.where(name), self.size, flags)

    def frames(self) -> Iterator[np.ndarray]:
        """Decoded 8-bit grayscale frames, in order."""
        for name, data in self.read_bytes():
            yield self.decode(name, data)

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


def sequence_folder(root: str | Path) -> Path:
    """`root` as a Path, or DatasetError when it is not a folder (every reader's first check)."""
    root = Path(root)
    if not root.is_dir():
        raise DatasetError(f"{root}: sequence folder not found")
    return root


def raise_problems(root: Path, layout: str, problems: list[str]) -> None:
    """One DatasetError listing every problem found in the sequence at `root`, if there is any: "invalid KITTI
    sequence" for `layout` KITTI, "invalid sequence" for ""."""
    if problems:
        kind = f"{layout} sequence" if layout else "sequence"
        raise DatasetError(f"{root}: invalid {kind}:\n  " + "\n  ".join(problems))


def require_regular(root: Path, layout: str, text_files: list[Path]) -> None:
    """DatasetError (raise_problems) when a text file of the sequence exists but cannot be read to an end
    (check_regular), before anything reads it."""
    raise_problems(root, layout, check_regular(text_files, set(text_files)))


def check_regular(paths: list[Path], text_files: set[Path]) -> list[str]:
    """The files among `paths` that exist but cannot be read to an end: not regular files (a device such as
    /dev/zero, a pipe, a folder) or text files beyond MAX_TEXT_BYTES. Never opens them."""
    problems = []
    for p in paths:
        if not (p.exists() or p.is_symlink()):
            continue
        if regular_file_problem(p) is not None:  # a stat: never opens it
            problems.append(
                f"{p}: not a regular file (a device, pipe, folder or broken link); expected the file itself"
            )
        elif p in text_files and p.stat().st_size > MAX_TEXT_BYTES:
            problems.append(f"{p}: {p.stat().st_size / 2**20:.0f} MB, more than a sequence's {p.name} can be")
    return problems


def read_text(path: Path) -> str:
    """A sequence's text file (a regular file of at most MAX_TEXT_BYTES, UTF-8), or DatasetError naming it."""
    return read_text_bounded(path, MAX_TEXT_BYTES, "a text file", DatasetError)


def row_count(path: Path) -> int:
    """The number of non-blank lines of a sequence's text file (read_text): its rows, one a pose or frame."""
    return sum(1 for line in read_text(path).splitlines() if line.strip())


def number_rows(path: Path, count: int, expected: str) -> Iterator[tuple[int, list[float]]]:
    """Each non-blank line of a text file of numbers (a pose a line): its line number and its `count` finite
    numbers; any other line is a DatasetError naming the file and line, and saying `expected`."""
    for n, line in enumerate(read_text(path).splitlines(), start=1):
        if not line.strip():
            continue
        try:
            values = [float(v) for v in line.split()]
        except ValueError:
            raise DatasetError(f"{path}:{n}: not numbers: {line.strip()[:60]!r}") from None
        if len(values) != count or not np.isfinite(values).all():
            raise DatasetError(f"{path}:{n}: {len(values)} values; expected {expected}")
        yield n, values


def key_bytes(path: Path) -> bytes:
    """A key file's content for identities and cache keys: "-" when missing, a marker when it cannot be read (a
    FIFO, a device, too large: validation names it). Never blocks."""
    if not (path.exists() or path.is_symlink()):
        return b"-"
    try:
        return read_bounded(path, MAX_TEXT_BYTES)
    except SlamRunError:
        return b"-unreadable-"


def time_problem(path: Path, lineno: int, token: str, value: float) -> str | None:
    """Why `value` (written `token` on line `lineno`) cannot be a frame time in seconds, or None."""
    if not math.isfinite(value):
        return f"{path}:{lineno}: {token!r} is not a finite time in seconds"
    if abs(value) > MAX_TIME_S:
        return f"{path}:{lineno}: {token!r} s is beyond {MAX_TIME_S:.0e} s; expected a time in seconds"
    return None


def image_path_problem(path: Path, lineno: int, name: str) -> str | None:
    """Why `name` (listed on line `lineno` of `path`) is not a relative path to an image inside the sequence folder,
    or None."""
    inside = not Path(name).is_absolute() and ".." not in Path(name).parts
    if name.lower().endswith(IMAGE_SUFFIXES) and inside and name.isprintable():
        return None
    return f"{path}:{lineno}: {name[:80]!r} is not an image path inside the sequence folder"


FrameRow = tuple[str, float, str]  # a listed frame: its time as written, in seconds, its image's path


def read_frame_list(
    path: Path, problems: list[str], row: Callable[[list[str], str], FrameRow | str], what: str
) -> tuple[list[str], np.ndarray | None]:
    """A listing of frames, one row each (blank lines and # comments skipped): `row` turns a row's cells (and its
    line) into a FrameRow, or says why it cannot; each time and image path is checked and the times must increase
    (`what` names them). (image paths, times), or ([], None) with the first problem added to `problems`."""
    names, stamps = [], []
    for n, line in enumerate(read_text(path).splitlines(), start=1):
        cells = line.split()
        if not cells or cells[0].startswith("#"):
            continue
        parsed = row(cells, line)
        if isinstance(parsed, str):
            problems.append(f"{path}:{n}: {parsed}")
            return [], None
        token, t, name = parsed
        if problem := time_problem(path, n, token[:60], t) or image_path_problem(path, n, name):
            problems.append(problem)
            return [], None
        stamps.append(t)
        names.append(name)
    if problem := frame_list_problem(path, stamps, what):
        problems.append(problem)
        return [], None
    return names, np.array(stamps)


def frame_list_problem(path: Path, stamps: list | np.ndarray, what: str) -> str | None:
    """Why the frames listed in `path` (their `stamps`, in file order) are no sequence: none listed, or `what` (times,
    frame numbers, timestamps) not strictly increasing, naming the first row that is not; or None."""
    if len(stamps) == 0:
        return f"{path}: no frame listed"
    bad = np.flatnonzero(np.diff(np.asarray(stamps)) <= 0)
    if len(bad):
        return f"{path}: {what} not strictly increasing (row {int(bad[0]) + 2} of the frames)"
    return None


def camera_problem(calibration: Path, camera: CameraFile) -> str | None:
    """Why the calibration in `calibration` cannot give a method a usable view (slamrun.core.camera's
    rectification_problem), named with the file; None when it can."""
    problem = rectification_problem(camera)
    return None if problem is None else f"{calibration}: {problem}"


def finite_groundtruth(traj: Trajectory, path: Path) -> Trajectory:
    """`traj` as read from the ground-truth file `path`; DatasetError naming the file and the first line where a row
    holds NaN or an infinity (a reader drops such rows: the runs would be evaluated on the frames left)."""
    n = traj.report.n_nonfinite_dropped
    if n:
        line = nonfinite_line(path)
        where = f"{path}:{line}" if line else str(path)
        raise DatasetError(
            f"{where}: {n} row(s) hold NaN or an infinite value; ground truth must be finite (leave out the row of a "
            "time without a pose)"
        )
    return traj


def read_groundtruth(path: Path, read: Callable[[Path], Trajectory]) -> Trajectory:
    """The ground truth `read` reads from `path`, every row finite (finite_groundtruth); a format error as a
    DatasetError."""
    try:
        return finite_groundtruth(read(path), path)
    except TrajectoryFormatError as exc:
        raise DatasetError(str(exc)) from None


def nonfinite_line(path: Path) -> int | None:
    """The number of the first line of `path` holding a NaN or an infinite number, or None."""
    try:
        text = read_text(path)
    except DatasetError:
        return None
    for n, line in enumerate(text.splitlines(), start=1):
        for cell in line.split("#", 1)[0].replace(",", " ").split():
            try:
                if not math.isfinite(float(cell)):
                    return n
            except ValueError:
                continue
    return None


def check_positions(traj: Trajectory, path: Path, columns: tuple[int, ...] = (1, 2, 3)) -> None:
    """DatasetError naming `path` (and the line: the first whose values at `columns` are not plausible) when a
    position of `traj` is infinite or beyond MAX_POSITION_M (NaN marks a frame without a pose)."""
    pos = traj.positions
    with np.errstate(invalid="ignore"):
        bad = np.isinf(pos) | (np.abs(pos) > MAX_POSITION_M)
    if not bad.any():
        return
    value = float(pos[bad][0])
    line = implausible_line(path, columns)
    where = f"{path}:{line[0]}" if line else str(path)
    value = line[1] if line else value
    raise DatasetError(
        f"{where}: a position of {value:g} m; ground truth must be finite and within {MAX_POSITION_M:.0e} m of the "
        "origin"
    )


def implausible_line(path: Path, columns: tuple[int, ...]) -> tuple[int, float] | None:
    """(line number, value) of the first row of a ground-truth file whose values at `columns` are infinite or
    beyond MAX_POSITION_M, or None."""
    try:
        text = read_text(path)
    except DatasetError:
        return None
    for n, line in enumerate(text.splitlines(), start=1):
        cells = line.split("#", 1)[0].replace(",", " ").split()
        for c in columns:
            try:
                v = float(cells[c])
            except (IndexError, ValueError):
                continue
            if math.isinf(v) or abs(v) > MAX_POSITION_M:
                return n, v
    return None


def folder_identity(key_files: list[Path], images_dir: Path, names: list[str]) -> str:
    """A digest of a sequence whose frames are files: the key files in full, the frames by name, size and first
    4 KiB (independent of paths and dates, so a moved or copied dataset keeps its runs). Never blocks."""
    import hashlib  # here: reading a ground-truth file (evaluate) never needs it

    h = hashlib.sha256()
    for p in key_files:
        h.update(p.name.encode() + b"\0" + key_bytes(p) + b"\0")
    for name in names:
        p = images_dir / name
        head = read_head(p)
        if head is None:
            h.update(f"{name}|missing".encode())
        else:
            h.update(f"{name}|{p.stat().st_size}|".encode() + hashlib.sha256(head).digest())
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
        row, distance = nearest(t, times)
        ok = distance <= tolerance_s
        pos[ok], quat[ok] = gt.positions[row[ok]], gt.quaternions[row[ok]]
    return Trajectory(np.asarray(times, float), pos, quat)


def transform_poses(traj: Trajectory, right: np.ndarray) -> Trajectory:
    """Each pose T_WB of `traj` times the fixed 4x4 `right` (e.g. T_BC: body poses to camera poses)."""
    from slamrun.core.trajectory import quat_to_rotmat, rotmat_to_quat

    ok = np.isfinite(traj.positions).all(axis=1) & np.isfinite(traj.quaternions).all(axis=1)
    new_pos = np.full_like(traj.positions, np.nan)
    quats = np.full_like(traj.quaternions, np.nan)
    rot = quat_to_rotmat(traj.quaternions[ok])
    new_pos[ok] = np.einsum("nij,j->ni", rot, right[:3, 3]) + traj.positions[ok]
    quats[ok] = rotmat_to_quat(rot @ right[:3, :3])
    return Trajectory(traj.timestamps, new_pos, quats)
