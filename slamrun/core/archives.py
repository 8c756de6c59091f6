"""Zip archives from outside, read with bounds: every member's stated size is checked before anything is inflated
(against a bound per member and for the whole archive), and the bytes actually inflated are counted against it, so
a member that holds more than it states is refused too. A zip bomb or a member of gigabytes ends in one error
naming the archive and the member, in bounded time and memory; a corrupt member (its CRC, its data) the same.
"""

from __future__ import annotations

import io
import zipfile
import zlib
from typing import BinaryIO

from slamrun.errors import SlamRunError

MiB = 2**20
CHUNK = MiB
# what zipfile and zlib raise on a damaged archive or member (RuntimeError: encrypted; NotImplementedError: a
# compression method this Python lacks)
ZIP_ERRORS = (zipfile.BadZipFile, zlib.error, EOFError, OSError, RuntimeError, NotImplementedError, ValueError)


def files_of(zf: zipfile.ZipFile) -> list[zipfile.ZipInfo]:
    """The members that are files (folders left out), in the archive's order."""
    return [info for info in zf.infolist() if not info.is_dir()]


def stated_total(infos: list[zipfile.ZipInfo]) -> int:
    """What the members say they unpack to, in all."""
    return sum(info.file_size for info in infos)


def _too_large(where: str, size: int, limit: int, what: str) -> str:
    return f"{where}: {size:,} bytes unpacked; {what} is at most {limit:,} bytes"


def read_member(
    zf: zipfile.ZipFile, info: zipfile.ZipInfo, where: str, limit: int, what: str, error: type[SlamRunError]
) -> bytes:
    """A member's bytes: refused before inflating when it states more than `limit`, and while inflating when it
    gives more than it states (never more than min(stated, limit) + one chunk is inflated); a damaged member
    (its CRC, its data) is `error` naming `where`."""
    if info.file_size > limit:
        raise error(_too_large(where, info.file_size, limit, what))
    out = io.BytesIO()
    copy_member(zf, info, out, where, error)
    return out.getvalue()


def copy_member(
    zf: zipfile.ZipFile, info: zipfile.ZipInfo, out: BinaryIO, where: str, error: type[SlamRunError]
) -> int:
    """Inflate a member into `out`, counting its bytes against its stated size (a member that gives more is
    `error`, as is a damaged one: an error reading it, never one writing `out`); returns the bytes written."""
    size = 0
    try:
        src = zf.open(info)
    except ZIP_ERRORS as exc:
        raise error(f"{where}: a damaged member ({exc})") from None
    with src:
        while True:
            try:
                chunk = src.read(CHUNK)
            except ZIP_ERRORS as exc:
                raise error(f"{where}: a damaged member ({exc})") from None
            if not chunk:
                return size
            size += len(chunk)
            if size > info.file_size:
                raise error(f"{where}: holds more than the {info.file_size:,} bytes it states; refused")
            out.write(chunk)
