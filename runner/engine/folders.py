"""Which folders slamrun may write into: names that become path parts, the results folder it owns."""

from __future__ import annotations

from pathlib import Path

RESULTS_MARKER = ".slamrun-results"  # in every results folder slamrun created
RESULTS_OWNED_BY = (RESULTS_MARKER, "ledger.sqlite", "runner.lock")  # any of them: a folder of slamrun's


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


def results_folder_problem(results: Path) -> str | None:
    """Why slamrun may not write its results into `results`, or None: a folder that holds files and none of
    slamrun's (a ledger, its marker) is someone else's, and its results.csv or report would be overwritten."""
    if not results.exists():
        return None
    if not results.is_dir():
        return f"{results} exists and is not a folder"
    if not any(results.iterdir()) or any((results / name).exists() for name in RESULTS_OWNED_BY):
        return None
    return (
        f"{results} is not a slamrun results folder (it holds files, and no ledger.sqlite or {RESULTS_MARKER}); "
        "slamrun would overwrite its results.csv, report/ and spec.resolved.yaml: choose a new or empty folder"
    )


def claim_results_folder(results: Path) -> None:
    """Mark a results folder as slamrun's (after its lock is held)."""
    marker = results / RESULTS_MARKER
    if not marker.exists():
        marker.write_text("slamrun results folder: ledger.sqlite, runs/, results.csv and report/ are written here\n")
