"""Which campaigns a served folder holds, and the guard every file the server reads for a URL passes."""

from __future__ import annotations

import os
import re
from pathlib import Path

from runner.errors import SlamRunError

LEDGER = "ledger.sqlite"
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


def served_file(root: Path, relative: str) -> Path | None:
    """The regular file `relative` names inside `root`, or None when it names anything else: an absolute path,
    a `..` or empty part, a backslash, a NUL, an encoded separator left in the path (`%2f`, `%5c`, `%2e%2e`
    decoded once already by the server), a hidden part (`.cache`, the ledger's `-wal`), or a file a symbolic
    link takes outside `root`. The caller opens the returned path; `root` must exist."""
    if not relative or len(relative) > 1024 or "\\" in relative or "\x00" in relative or "%" in relative:
        return None
    parts = relative.split("/")
    if any(p in ("", ".", "..") or p.startswith(".") for p in parts):
        return None
    base = Path(root).resolve()
    try:
        target = (base / relative).resolve(strict=True)
    except (OSError, RuntimeError):  # missing, a loop of links
        return None
    if not target.is_relative_to(base) or not target.is_file():
        return None
    return target
