"""Which campaigns a served folder holds, and the guard every file the server reads for a URL passes."""

from __future__ import annotations

import os
import re
import stat
from pathlib import Path
from typing import BinaryIO

from slamrun.errors import SlamRunError
from slamrun.results.files import LEDGER

MAX_CAMPAIGNS = 500  # a folder listing more is refused: the server lists, it does not crawl
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,127}$")


def campaigns(root: Path) -> dict[str, Path]:
    """The campaigns under `root` by name: `root` itself when it is a campaign's results folder (it holds a
    ledger), else each direct subfolder that is one (a folder of several campaigns: `results/` of `make
    campaign`). Names are the folders' names, sorted; symbolic links are not followed."""
    root = Path(root)
    if not root.is_dir():
        raise SlamRunError(f"{root}: no such folder; expected a campaign's results folder (it holds {LEDGER})")
    if (root / LEDGER).is_file():
        return {root.resolve().name: root}
    found: dict[str, Path] = {}
    with os.scandir(root) as entries:
        for entry in entries:
            if len(found) > MAX_CAMPAIGNS:
                raise SlamRunError(f"{root}: over {MAX_CAMPAIGNS} campaigns; serve one campaign's folder instead")
            if _NAME.match(entry.name) and entry.is_dir(follow_symlinks=False):
                if os.path.isfile(os.path.join(entry.path, LEDGER)):
                    found[entry.name] = Path(entry.path)
    return dict(sorted(found.items()))


def _parts(relative: str) -> list[str] | None:
    """The path's parts, or None when it is no plain relative path: absolute, a `..`, `.` or empty part, a
    backslash, a NUL, a `%` (an encoded separator left after the server decoded it once), a hidden part (`.cache`,
    the ledger's `-wal`), or over 1024 characters."""
    if not relative or len(relative) > 1024 or "\\" in relative or "\x00" in relative or "%" in relative:
        return None
    parts = relative.split("/")
    if any(p in ("", ".", "..") or p.startswith(".") for p in parts):
        return None
    return parts


def open_served(root: Path, relative: str) -> BinaryIO | None:
    """The regular file `relative` names inside `root`, opened for reading, or None when it names anything else
    (`_parts`), or when any part of it is a symbolic link, or the file is not a regular file. Each part is opened
    relative to the folder opened before it, without following a link (O_NOFOLLOW): no part can be swapped for a
    link between a check and the open, whatever another process does in the folder."""
    parts = _parts(relative)
    if parts is None:
        return None
    flags = os.O_RDONLY | os.O_CLOEXEC
    try:
        fd = os.open(root, flags | os.O_DIRECTORY)
    except OSError:
        return None
    try:
        for part in parts[:-1]:
            nxt = os.open(part, flags | os.O_DIRECTORY | os.O_NOFOLLOW, dir_fd=fd)
            os.close(fd)
            fd = nxt
        nxt = os.open(parts[-1], flags | os.O_NOFOLLOW | os.O_NONBLOCK, dir_fd=fd)  # a FIFO never blocks the open
        os.close(fd)
        fd = nxt
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            os.close(fd)
            return None
    except OSError:  # missing, a link (ELOOP), not a folder: none of these is served
        os.close(fd)
        return None
    return os.fdopen(fd, "rb")
