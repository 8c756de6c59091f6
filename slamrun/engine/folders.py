"""Which folders slamrun may write into: names that become path parts, and the one guard every output folder goes
through (a campaign's results, the view cache, a report, verify's folder) before anything is written there."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from slamrun.errors import SlamRunError
from slamrun.results import files


class FolderRefused(SlamRunError):
    """An output folder slamrun may not write into (someone else's files, another campaign's results)."""


@dataclass(frozen=True)
class OutputFolder:
    """A kind of folder slamrun writes: how it recognises one of its own, and what it would overwrite in another."""

    what: str  # "results folder"
    marker: str  # the file slamrun leaves in every folder of this kind it made
    owned_by: tuple[str, ...]  # any of these names in it: a folder of slamrun's
    writes: str  # what slamrun would do to someone else's folder
    holds_views: bool = False  # a view cache: a subfolder holding a prepared view (view.json) makes it slamrun's
    inside: OutputFolder | None = None  # also slamrun's when its parent is slamrun's folder of this kind

    def owns(self, folder: Path) -> bool:
        """Whether `folder` (an existing folder) is one slamrun made."""
        if any((folder / name).exists() for name in self.owned_by):
            return True
        if self.inside is not None and self.inside.owns(folder.parent):
            return True
        return self.holds_views and any(p.is_dir() and (p / "view.json").is_file() for p in folder.iterdir())


RESULTS = OutputFolder(
    "results folder",
    files.MARKER,
    (files.MARKER, files.LEDGER, files.LOCK),
    "overwrite its results.csv, report/ and spec.resolved.yaml",
)
CACHE = OutputFolder(
    "view cache",
    ".slamrun-cache",
    (".slamrun-cache",),
    "delete every subfolder in it that is not a prepared view",
    holds_views=True,
)
REPORT = OutputFolder(
    "report folder",
    ".slamrun-report",
    (".slamrun-report",),
    "overwrite its index.html, figures/ and tables/",
    inside=RESULTS,
)
VERIFY = OutputFolder(
    "verify folder",
    ".slamrun-verify",
    (".slamrun-verify", "verify.json"),
    "overwrite its verify.json and verify.md and write data/, views/ and a campaign per method into it",
)
RESULTS_MARKER = RESULTS.marker


def path_part_problem(name: str) -> str | None:
    """Why `name` cannot be one part of a path below a root (a sequence name, a method label), or None."""
    if not name:
        return "is empty"
    if name in (".", ".."):
        return f"{name!r} would leave its folder"
    bad = [c for c in ("/", "\\", "\0") if c in name]
    if bad:
        return f"{name!r} holds {' and '.join(repr(c) for c in bad)}: a name, not a path, is expected"
    return None


def output_folder_problem(folder: Path, kind: OutputFolder) -> str | None:
    """Why slamrun may not write into `folder` as its `kind` of folder, or None: a folder that does not exist yet, an
    empty one, or one slamrun made (its marker, or the files slamrun keeps there). Any other folder holds someone
    else's files, which slamrun would overwrite or delete. Reads only."""
    if not folder.exists():
        if folder.is_symlink():
            return f"{folder} is a broken link"
        return None
    if not folder.is_dir():
        return f"{folder} exists and is not a folder"
    try:
        if not any(folder.iterdir()) or kind.owns(folder):
            return None
    except OSError as exc:
        return f"{folder} cannot be read ({exc.strerror})"
    return (
        f"{folder} is not a slamrun {kind.what} (it holds files, and no {' or '.join(kind.owned_by)}); slamrun "
        f"would {kind.writes}: choose a new or empty folder"
    )


def require_output_folder(folder: Path, kind: OutputFolder) -> None:
    """FolderRefused when `output_folder_problem` finds one."""
    if why := output_folder_problem(folder, kind):
        raise FolderRefused(why)


def claim_output_folder(folder: Path, kind: OutputFolder) -> None:
    """Make `folder` (checked first) and mark it as slamrun's `kind` of folder."""
    folder.mkdir(parents=True, exist_ok=True)
    marker = folder / kind.marker
    if not marker.exists():
        marker.write_text(f"slamrun {kind.what}: slamrun writes here\n")


def claim_results_folder(results: Path) -> None:
    """Mark a results folder as slamrun's (after its lock is held)."""
    claim_output_folder(results, RESULTS)


def cache_overlap_problem(cache: Path, results: Path, datasets: list[Path]) -> str | None:
    """Why `cache` cannot hold the view cache beside these results and datasets, or None: the cache deletes every
    subfolder of its own that is not a whole view, so it may neither be nor hold the results or a dataset."""
    for what, folder in [("the results folder", results)] + [("the dataset folder", d) for d in datasets]:
        if folder == cache or cache in folder.parents:
            where = "is" if folder == cache else "holds"
            return (
                f"{cache} {where} {what} {folder}; the view cache deletes what in it is not a prepared view: give "
                "the cache a folder of its own"
            )
    return None
