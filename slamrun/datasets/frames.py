"""A sequence's frames read with bounds: every frame a regular file (or a zip member) of 1 byte to MAX_FRAME_BYTES,
opened without blocking (a FIFO, a device such as /dev/zero, a socket is refused, never read), and of the
calibration's size. Validation checks every frame's file and header (a few KiB each); view preparation decodes
every frame and refuses one that does not decode or has another size, naming it: a dataset error, never a method's.
"""

from __future__ import annotations

import os
import stat
import struct
import zipfile
import zlib
from pathlib import Path

import numpy as np

from slamrun.core.inputs import MiB, read_bounded, regular_file_problem
from slamrun.errors import DatasetError

GRAYSCALE, UNCHANGED = 0, -1  # OpenCV's IMREAD_GRAYSCALE and IMREAD_UNCHANGED

# No dataset's frame comes near it: EuRoC's 752x480 and KITTI's 1241x376 PNGs are about 0.4 MB, TUM-Mono's
# 1280x1024 JPEGs 0.3 MB; even an uncompressed 4096x4096 16-bit PNG is 32 MiB.
MAX_FRAME_BYTES = 64 * MiB
HEAD_BYTES = 4096  # what validation reads of each frame: its header, with the image's size
MAX_LISTED = 3  # problems of the same kind listed before "and N more"


def header_size(head: bytes) -> tuple[int, int] | None:
    """(width, height) from the first bytes of a PNG, JPEG, binary PGM/PPM or BMP; None when the header is not
    one of them or lies beyond `head` (the frame's decoding decides then)."""
    if head[:8] == b"\x89PNG\r\n\x1a\n" and head[12:16] == b"IHDR" and len(head) >= 24:
        return struct.unpack(">II", head[16:24])
    if head[:2] == b"\xff\xd8":
        return _jpeg_size(head)
    if head[:2] in (b"P5", b"P6", b"P2", b"P3"):
        tokens = b" ".join(line.split(b"#", 1)[0] for line in head[2:200].split(b"\n")).split()
        if len(tokens) >= 2 and tokens[0].isdigit() and tokens[1].isdigit():
            return int(tokens[0]), int(tokens[1])
        return None
    if head[:2] == b"BM" and len(head) >= 26:
        w, h = struct.unpack("<ii", head[18:26])
        return abs(w), abs(h)
    return None


def _jpeg_size(head: bytes) -> tuple[int, int] | None:
    i = 2
    while i + 9 < len(head):
        if head[i] != 0xFF:
            return None
        marker = head[i + 1]
        if marker == 0xFF:  # fill byte
            i += 1
            continue
        if 0xC0 <= marker <= 0xCF and marker not in (0xC4, 0xC8, 0xCC):  # a start of frame: SOF0..SOF15
            h, w = struct.unpack(">HH", head[i + 5 : i + 9])
            return w, h
        if marker in (0xD8, 0x01) or 0xD0 <= marker <= 0xD7:  # markers without a length
            i += 2
            continue
        i += 2 + struct.unpack(">H", head[i + 2 : i + 4])[0]
    return None


def frame_file_problem(path: Path) -> str | None:
    """Why `path` cannot be a frame (missing, not a regular file, empty, beyond MAX_FRAME_BYTES), or None. Never
    opens it."""
    return _frame_stat(path)[0]


def _frame_stat(path: Path) -> tuple[str | None, os.stat_result | None]:
    try:
        st = os.stat(path)
    except (OSError, ValueError):
        st = None
    if st is None or not stat.S_ISREG(st.st_mode):
        return regular_file_problem(path, "a frame") or f"{path}: cannot be read as a frame", None
    if st.st_size == 0:
        return f"{path}: empty (0 bytes); expected an image", None
    if st.st_size > MAX_FRAME_BYTES:
        return f"{path}: {st.st_size:,} bytes; a frame is at most {MAX_FRAME_BYTES:,} bytes", None
    return None, st


# The size each frame's header announces, per file version (path, size, modification time, inode): a sequence is
# opened many times in one process (planning, validation, preparation), its frames' headers are read once.
_ANNOUNCED: dict[tuple, tuple[int, int] | None] = {}
_MAX_REMEMBERED = 1_000_000


def announced_size(path: Path, st: os.stat_result) -> tuple[int, int] | None:
    """The size the header of frame `path` (a regular file, `st` its status) announces, or None."""
    key = (str(path), st.st_size, st.st_mtime_ns, st.st_ino)
    if key not in _ANNOUNCED:
        if len(_ANNOUNCED) >= _MAX_REMEMBERED:
            _ANNOUNCED.clear()
        head = read_head(path)
        _ANNOUNCED[key] = header_size(head) if head else None
    return _ANNOUNCED[key]


def read_head(path: Path, n: int = HEAD_BYTES) -> bytes | None:
    """The first `n` bytes of a regular file, or None when it is missing or not a regular file. Never blocks."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except (OSError, ValueError):
        return None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            return None
        return os.read(fd, n)
    except OSError:
        return None
    finally:
        os.close(fd)


def read_frame(path: Path) -> bytes:
    """A frame's bytes, or DatasetError naming it (missing, not a regular file, empty, too large)."""
    data = read_bounded(path, MAX_FRAME_BYTES, "a frame", DatasetError)
    if not data:
        raise DatasetError(f"{path}: empty (0 bytes); expected an image")
    return data


def member_problem(zip_path: Path, info: zipfile.ZipInfo) -> str | None:
    """Why a zip member cannot be a frame (empty, or inflating beyond MAX_FRAME_BYTES), from the zip's directory."""
    if info.file_size == 0:
        return f"{zip_path}: member {info.filename}: empty (0 bytes); expected an image"
    if info.file_size > MAX_FRAME_BYTES:
        return (
            f"{zip_path}: member {info.filename}: inflates to {info.file_size:,} bytes; a frame is at most "
            f"{MAX_FRAME_BYTES:,} bytes"
        )
    return None


def read_member(zf: zipfile.ZipFile, zip_path: Path, name: str, n: int | None = None) -> bytes:
    """A zip member's bytes (its first `n` only, when given), inflating at most MAX_FRAME_BYTES; DatasetError
    naming the zip and the member otherwise."""
    try:
        info = zf.getinfo(name)
        problem = member_problem(zip_path, info)
        if problem is not None:
            raise DatasetError(problem)
        with zf.open(info) as member:
            return member.read(MAX_FRAME_BYTES + 1 if n is None else n)
    except KeyError:
        raise DatasetError(f"{zip_path}: member {name} not found; re-download the sequence") from None
    except (zipfile.BadZipFile, NotImplementedError, zlib.error, EOFError, OSError) as exc:
        raise DatasetError(f"{zip_path}: member {name} unreadable ({exc}); re-download the sequence") from None


def decode(
    data: bytes,
    where: str,
    size: tuple[int, int] | None,
    flags: int = GRAYSCALE,
    source: str = "the calibration",
) -> np.ndarray:
    """A frame decoded, or DatasetError naming `where` (it does not decode, or is not `size` = (width, height), the
    input size `source` gives). A header announcing another size is refused before anything is decoded."""
    announced = header_size(data[:HEAD_BYTES])
    if size is not None and announced is not None and announced != size:
        raise DatasetError(size_problem(where, announced, size, source))
    import cv2  # OpenCV only when a frame is decoded: reading a sequence's lists and times does not need it

    try:
        img = cv2.imdecode(np.frombuffer(data, np.uint8), flags)
    except cv2.error:
        img = None
    if img is None:
        raise DatasetError(f"{where}: cannot be decoded as an image")
    found = (img.shape[1], img.shape[0])
    if size is not None and found != size:
        raise DatasetError(size_problem(where, found, size, source))
    return img


def size_problem(where: str, found: tuple[int, int], size: tuple[int, int], source: str = "the calibration") -> str:
    return f"{where}: {found[0]}x{found[1]}, but {source} gives input size {size[0]}x{size[1]}"


def check_files(
    images: Path, names: list[str], size: tuple[int, int] | None, problems: list[str], source: str = "the calibration"
) -> None:
    """Every frame `images/name` a regular file of 1 byte to MAX_FRAME_BYTES whose header (where it names a size)
    is `size`; the first frame decoded. Problems of frames listed up to MAX_LISTED, then counted."""
    found: list[str] = []
    for name in names:
        path = images / name
        problem, st = _frame_stat(path)
        if st is not None and size is not None:
            announced = announced_size(path, st)
            if announced is not None and announced != size:
                problem = size_problem(str(path), announced, size, source)
        if problem is not None:
            found.append(problem)
    if not found and names:
        try:
            decode(read_frame(images / names[0]), str(images / names[0]), size, UNCHANGED, source)
        except DatasetError as exc:
            found.append(str(exc))
    problems.extend(_listed(found))


def check_listed(
    root: Path, names: list[str], listing: str, size: tuple[int, int], problems: list[str], source: str
) -> None:
    """The frames a listing (`listing`: rgb.txt, associations.txt) names below `root`: each present (else how many
    are missing, and one), then `check_files`."""
    missing = [n for n in names if not ((root / n).exists() or (root / n).is_symlink())]
    if missing:
        problems.append(f"{root}: {len(missing)} frame(s) listed in {listing} missing (e.g. {missing[0]})")
    else:
        check_files(root, names, size, problems, source)


def check_members(
    zf: zipfile.ZipFile,
    zip_path: Path,
    names: list[str],
    size: tuple[int, int] | None,
    problems: list[str],
    source: str = "the calibration",
) -> None:
    """`check_files` for frames that are members of a zip: sizes from its directory, the header of each."""
    found: list[str] = []
    for name in names:
        try:
            problem = member_problem(zip_path, zf.getinfo(name))
            if problem is None and size is not None:
                announced = header_size(read_member(zf, zip_path, name, HEAD_BYTES))
                if announced is not None and announced != size:
                    problem = size_problem(f"{zip_path}: member {name}", announced, size, source)
        except DatasetError as exc:
            problem = str(exc)
        if problem is not None:
            found.append(problem)
    if not found and names:
        try:
            data = read_member(zf, zip_path, names[0])
            decode(data, f"{zip_path}: member {names[0]}", size, UNCHANGED, source)
        except DatasetError as exc:
            found.append(str(exc))
    problems.extend(_listed(found))


def _listed(found: list[str]) -> list[str]:
    if len(found) <= MAX_LISTED:
        return found
    return [*found[:MAX_LISTED], f"... and {len(found) - MAX_LISTED} more frame(s) alike"]
