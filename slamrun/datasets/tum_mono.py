"""TUM monoVO (TUM-Mono): `sequence_XX/` with `images.zip` (or `images/`), `times.txt` (`id timestamp
exposure_ms`), `camera.txt` (the FOV camera), the photometric calibration (`pcalib.txt`, `vignette.png`) and
`groundtruthSync.txt` (the start and end segments' poses, NaN rows between). Opened and validated here (every
problem reported with its file); written synthetically with its photometric model; downloaded as the site's
`sequence_XX.zip`.
"""

from __future__ import annotations

import functools
import io
import math
import os
import zipfile
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from slamrun.core.camera import CameraFile, read_camera_txt
from slamrun.core.inputs import read_bounded
from slamrun.core.trajectory import Trajectory
from slamrun.datasets import frames
from slamrun.datasets.protocol import Download, Layout, Placed
from slamrun.datasets.sequence import (
    IMAGE_SUFFIXES,
    Sequence,
    camera_problem,
    check_positions,
    check_regular,
    key_bytes,
    raise_problems,
    read_text,
    sequence_folder,
    time_problem,
)
from slamrun.errors import DatasetError

if TYPE_CHECKING:
    from slamrun.datasets.synth import Synth

REQUIRED = ("times.txt", "camera.txt", "pcalib.txt", "vignette.png")
TEXT_FILES = ("times.txt", "camera.txt", "pcalib.txt", "groundtruthSync.txt")
MAX_TESTED_BYTES = 512 * 2**20  # images.zip's members are all inflated to test their CRCs up to this total


def unusable_files(root: Path) -> list[str]:
    """The sequence's files that exist but cannot be read to an end: not regular files (a device such as
    /dev/zero, a pipe, a folder) or text files beyond MAX_TEXT_BYTES."""
    names = (*REQUIRED, "images.zip", "groundtruthSync.txt")
    return check_regular([root / n for n in names], {root / n for n in TEXT_FILES})


def read_groundtruth_sync(p: Path) -> Trajectory:
    """groundtruthSync.txt, NaN rows kept (they split the segments by row count); positions checked
    (`check_positions`)."""
    try:
        data = np.loadtxt(io.StringIO(read_text(p)), comments="#", ndmin=2)
    except ValueError as exc:
        raise DatasetError(f"{p}: not rows of 8 numbers ({str(exc)[:120]})") from None
    if data.shape[1] != 8:
        raise DatasetError(f"{p}: {data.shape[1]} columns, expected 'timestamp tx ty tz qx qy qz qw'")
    if np.any(np.diff(data[:, 0]) <= 0):
        raise DatasetError(f"{p}: timestamps are not strictly increasing")
    traj = Trajectory(data[:, 0], data[:, 1:4], data[:, 4:8])
    check_positions(traj, p)
    return traj


def open_sequence(root: str | Path) -> Sequence:
    """Open a sequence folder and validate it; raises one DatasetError listing every problem."""
    root = sequence_folder(root)
    problems: list[str] = []
    for name in REQUIRED:
        if not (root / name).exists():
            problems.append(f"{root / name}: missing")
    unusable = unusable_files(root)
    if unusable:  # reading them would never end, or exhaust memory
        raise_problems(root, "", problems + unusable)

    names, zip_path = _frame_names(root, problems)
    timestamps, exposures = _read_times(root / "times.txt", problems)
    camera = None
    if (root / "camera.txt").exists():
        try:
            camera = read_camera_txt(root / "camera.txt")
        except DatasetError as exc:
            problems.append(str(exc))
        if camera is not None and (problem := camera_problem(root / "camera.txt", camera)):
            problems.append(problem)
            camera = None

    if names is not None and timestamps is not None and len(names) != len(timestamps):
        problems.append(
            f"{root / 'times.txt'}: {len(timestamps)} lines but {len(names)} images; they must be equal "
            "(DSO silently writes zero timestamps otherwise)"
        )
    if timestamps is not None and len(timestamps) > 1 and np.any(np.diff(timestamps) <= 0):
        i = int(np.flatnonzero(np.diff(timestamps) <= 0)[0]) + 2
        problems.append(f"{root / 'times.txt'}:{i}: timestamps not strictly increasing")
    if names:
        _check_frames(root, names, zip_path, camera, problems)
    _check_pcalib(root / "pcalib.txt", problems)
    if camera is not None:
        _check_vignette(root / "vignette.png", camera, problems)
    raise_problems(root, "", problems)
    assert names is not None and timestamps is not None and camera is not None
    gt = root / "groundtruthSync.txt"
    return Sequence(
        root,
        tuple(names),
        timestamps,
        exposures,
        camera,
        zip_path,
        images_dir=None if zip_path else root / "images",
        layout="tum-mono",
        pcalib=root / "pcalib.txt",
        vignette=root / "vignette.png",
        camera_txt=root / "camera.txt",
        groundtruth_path=gt if gt.exists() else None,
        key_files=(root / "times.txt", root / "camera.txt", root / "pcalib.txt"),
        groundtruth_reader=(lambda: read_groundtruth_sync(gt)) if gt.exists() else None,
    )


def _frame_names(root: Path, problems: list[str]) -> tuple[list[str] | None, Path | None]:
    zip_path = root / "images.zip"
    if zip_path.exists():
        try:
            with zipfile.ZipFile(zip_path) as zf:
                names = sorted(n for n in zf.namelist() if n.lower().endswith(IMAGE_SUFFIXES))
                small = zip_path.stat().st_size < 50_000_000
                bad = zf.testzip() if small and sum(i.file_size for i in zf.infolist()) <= MAX_TESTED_BYTES else None
            if bad:
                problems.append(f"{zip_path}: member {bad} is corrupt; re-download the sequence")
        except (zipfile.BadZipFile, OSError) as exc:
            problems.append(f"{zip_path}: not a readable zip ({exc}); re-download or unpack it into images/")
            return None, None
        if not names:
            problems.append(f"{zip_path}: holds no images ({', '.join(IMAGE_SUFFIXES)})")
        return names, zip_path
    folder = root / "images"
    if folder.is_dir():
        names = sorted(p.name for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
        if not names:
            problems.append(f"{folder}: holds no images")
        return names, None
    problems.append(f"{root}: neither images.zip nor images/ found")
    return None, None


def _read_times(path: Path, problems: list[str]) -> tuple[np.ndarray | None, np.ndarray | None]:
    if not path.exists():
        return None, None
    rows = []
    for lineno, line in enumerate(read_text(path).splitlines(), start=1):
        body = line.split("#", 1)[0].split()
        if not body:
            continue
        try:
            rows.append([float(v) for v in body])
        except ValueError:
            problems.append(f"{path}:{lineno}: not a number in {line.strip()[:60]!r}")
            return None, None
        if len(rows[-1]) not in (2, 3):
            problems.append(f"{path}:{lineno}: {len(rows[-1])} values, expected 'id timestamp [exposure_ms]'")
            return None, None
        if problem := time_problem(path, lineno, body[1][:60], rows[-1][1]):
            problems.append(problem)
            return None, None
        if len(body) == 3 and not (0 < rows[-1][2] < 1e6):  # NaN fails it too
            problems.append(f"{path}:{lineno}: exposure {body[2][:60]!r}; expected a positive, finite number of ms")
            return None, None
    if not rows:
        problems.append(f"{path}: empty")
        return None, None
    width = {len(r) for r in rows}
    if len(width) > 1:
        problems.append(f"{path}: rows of mixed length; expected 'id timestamp exposure_ms' on every line")
        return None, None
    data = np.array(rows)
    return data[:, 1], (data[:, 2] if data.shape[1] == 3 else None)


def _check_frames(root: Path, names: list[str], zip_path: Path | None, cam: CameraFile | None, problems: list[str]):
    """Every frame (a member of images.zip, or a file of images/) within the frame bounds and of camera.txt's input
    size (slamrun.datasets.frames)."""
    size = (cam.camera.width, cam.camera.height) if cam is not None else None
    if zip_path is None:
        frames.check_files(root / "images", names, size, problems, "camera.txt")
        return
    try:
        with zipfile.ZipFile(zip_path) as zf:
            frames.check_members(zf, zip_path, names, size, problems, "camera.txt")
    except (zipfile.BadZipFile, OSError) as exc:
        problems.append(f"{zip_path}: not a readable zip ({exc}); re-download or unpack it into images/")


def _check_pcalib(path: Path, problems: list[str]) -> None:
    if not path.exists():
        return
    try:
        values = read_pcalib(path)
    except ValueError:
        problems.append(f"{path}: not numbers; expected 256 values of the inverse response")
        return
    if not np.isfinite(values).all():
        problems.append(f"{path}: values that are not finite; expected 256 numbers of the inverse response")
    elif len(values) != 256:
        problems.append(f"{path}: {len(values)} values, expected 256")
    elif np.any(np.diff(values) <= 0):
        problems.append(f"{path}: values not strictly increasing (the inverse response must be)")


def _check_vignette(path: Path, cam: CameraFile, problems: list[str]) -> None:
    """vignette.png decodes and is of camera.txt's input size (a header announcing another is refused before it is
    decoded)."""
    if not path.exists():
        return
    try:
        _vignette_image(path, (cam.camera.width, cam.camera.height))
    except DatasetError as exc:
        problems.append(str(exc))


def read_pcalib(path: Path) -> np.ndarray:
    return np.array(read_text(path).split(), dtype=float)


def _vignette_image(path: Path, size: tuple[int, int] | None = None) -> np.ndarray:
    data = read_bounded(path, frames.MAX_FRAME_BYTES, "the vignette", DatasetError)
    return frames.decode(data, str(path), size, frames.UNCHANGED, "camera.txt")


def sequence_identity(root: str | Path) -> str:
    """A short digest of a sequence's content as methods see it, for run keys: new data makes new runs.

    The small files in full (times.txt, camera.txt, pcalib.txt, vignette.png); the frames by name, size
    and CRC-32 from images.zip's directory (no decompression), or by name, size and first 4 KiB in images/.
    Independent of paths and file dates, so a moved or copied dataset keeps its runs. "none" when the
    folder has no times.txt (a synthetic sequence not generated yet).
    """
    root = Path(root)
    stamp = tuple(
        _stat_or_none(root / n)
        for n in ("times.txt", "camera.txt", "pcalib.txt", "vignette.png", "images.zip", "images")
    )
    return _identity(root, stamp)


def _stat_or_none(p: Path) -> tuple | None:
    try:
        st = p.stat()
        return (st.st_size, st.st_mtime_ns, st.st_ino)
    except OSError:
        return None


@functools.lru_cache(maxsize=4096)
def _identity(root: Path, stamp: tuple) -> str:
    import hashlib

    if stamp[0] is None:
        return "none"
    h = hashlib.sha256()
    for name in ("times.txt", "camera.txt", "pcalib.txt", "vignette.png"):
        h.update(name.encode() + b"\0" + key_bytes(root / name) + b"\0")
    zip_path = root / "images.zip"
    if zip_path.exists():
        try:
            with zipfile.ZipFile(zip_path) as zf:
                for info in zf.infolist():
                    h.update(f"{info.filename}|{info.file_size}|{info.CRC}\n".encode())
        except (zipfile.BadZipFile, OSError):
            h.update(b"unreadable zip|%d" % zip_path.stat().st_size)
    elif (root / "images").is_dir():
        for p in sorted((root / "images").iterdir()):
            head = frames.read_head(p) if p.suffix.lower() in IMAGE_SUFFIXES else None
            if head is not None:  # a frame (a FIFO or a device is never opened: validation names it)
                h.update(f"{p.name}|{p.stat().st_size}|".encode() + hashlib.sha256(head).digest())
    return h.hexdigest()[:10]


# ---------------------------------------------------------------------------------------------------- the layout


def recognise(root: Path) -> bool:
    """times.txt or camera.txt (and none of KITTI's image_0/ and calib.txt, which has a times.txt too)."""
    kitti = (root / "image_0").is_dir() or (root / "calib.txt").exists()
    return not kitti and ((root / "times.txt").exists() or (root / "camera.txt").exists())


def write_synthetic(tmp: Path, s: Synth) -> Placed:
    """The sequence in TUM-Mono's layout: JPEG frames in images.zip through a response curve, a vignette and
    per-frame exposures (times.txt), the FOV camera, and the ground truth of the start and end segments."""
    import cv2
    from scipy.spatial.transform import Rotation

    from slamrun.core.camera import write_camera_txt
    from slamrun.datasets import synth as sy

    n = s.frames
    cam = sy.default_camera(*s.size)
    vignette = sy.vignette_image(cam)
    t = 1.0 + np.arange(n) / sy.FPS
    exposure = 8.0 * (1.0 + 0.25 * np.sin(2 * np.pi * np.arange(n) / 97.0))
    with zipfile.ZipFile(tmp / "images.zip", "w", zipfile.ZIP_STORED) as zf:
        for i, img in s.images(cam, exposure, vignette):
            ok, jpg = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 95])
            entry = zipfile.ZipInfo(f"{i:05d}.jpg", date_time=(1980, 1, 1, 0, 0, 0))  # deterministic bytes
            zf.writestr(entry, jpg.tobytes())
    with open(tmp / "times.txt", "w") as f:
        for i in range(n):
            f.write(f"{i:05d} {t[i]:.6f} {exposure[i]:.6f}\n")
    out_size = (640, 480) if s.size[0] >= 640 and s.size[1] >= 480 else s.size  # TUM-Mono's output size
    write_camera_txt(tmp / "camera.txt", cam, "crop", out_size)
    (tmp / "pcalib.txt").write_text(" ".join(f"{v:.9g}" for v in sy.inverse_response()) + "\n")
    cv2.imwrite(str(tmp / "vignette.png"), np.rint(vignette / vignette.max() * 65535).astype(np.uint16))
    rots, positions = sy.camera_path(s.scene, n)
    gt = np.column_stack([t, positions, Rotation.from_matrix(rots).as_quat()])
    sy.savetxt(tmp / "groundtruth_full.txt", gt)
    n_seg = max(int(math.floor(sy.GT_FRACTION * n)), 3)
    gt_sync = gt.copy()
    gt_sync[n_seg : n - n_seg, 1:] = np.nan
    sy.savetxt(tmp / "groundtruthSync.txt", gt_sync)
    return []


URL = os.environ.get("SLAMRUN_TUM_MONO_URL", "https://vision.in.tum.de/mono/dataset")


def parse_numbers(text: str) -> list[int]:
    """'1-5,7,10-12' → [1, 2, 3, 4, 5, 7, 10, 11, 12], sorted, each once."""
    out: list[int] = []
    for part in text.split(","):
        part = part.strip()
        try:
            if "-" in part:
                a, b = (int(v) for v in part.split("-", 1))
                out += list(range(a, b + 1))
            elif part:
                out.append(int(part))
        except ValueError:
            raise DatasetError(f"--sequences {text!r}: expected numbers and ranges like 1-5,7") from None
    return sorted(set(out))


def parse_sequences(text: str) -> list[int]:
    """'1-5,7,10-12' → [1, 2, 3, 4, 5, 7, 10, 11, 12] (TUM-Mono numbers 1..50)."""
    out = parse_numbers(text)
    bad = [n for n in out if not 1 <= n <= 50]
    if bad:
        raise DatasetError(f"--sequences {text!r}: TUM-Mono has sequences 1 to 50, not {bad}")
    return out


def _archive(name: str, base: str) -> tuple[str, str] | None:
    """sequence_XX (or XX) → its folder and the site's sequence_XX.zip."""
    number = name.removeprefix("sequence_")
    if not (number.isdigit() and 1 <= int(number) <= 50):
        return None
    folder = f"sequence_{int(number):02d}"
    return folder, f"{base}/{folder}.zip"


LAYOUT = Layout(
    name="tum-mono",
    title="TUM monoVO (photometric calibration; ground truth at the start and end)",
    recognise=recognise,
    frame_list="times.txt",
    read=open_sequence,
    groundtruth_file="groundtruthSync.txt",
    default_metrics=("tum-mono",),
    synth=write_synthetic,
    download=Download(
        URL,
        _archive,
        "1 to 50",
        default=tuple(f"sequence_{n:02d}" for n in range(1, 51)),
        parse=lambda text: [f"sequence_{n:02d}" for n in parse_sequences(text)],
    ),
    identity=sequence_identity,
)
