"""Marks on a method's name: no view shows a method as best, bold or ranked first without saying that its runs there
tracked under the dataset's coverage_mark of the frames they were given (†) or diverged (‡). Every view of a dataset
(the terminal table, the report's tables and figures, the ranks, the live page) marks the same methods, from the
runs' own flags (results.csv's low_coverage and diverged), with one line under it saying what each mark means."""

from __future__ import annotations

import json
import math
from collections.abc import Iterable
from dataclasses import dataclass, field

from slamrun.results import catalogue as col
from slamrun.results.vocabulary import DIVERGED_FLAG_REL

LOW_COVERAGE = "†"
DIVERGED = "‡"


@dataclass
class Flags:
    """A method's done runs and how many of them are flagged."""

    done: int = 0
    low_coverage: int = 0
    diverged: int = 0
    coverage_mark: set = field(default_factory=set)  # the thresholds the runs were judged by (their eval_settings)
    diverged_at: set = field(default_factory=set)

    @property
    def symbol(self) -> str:
        return (LOW_COVERAGE if self.low_coverage else "") + (DIVERGED if self.diverged else "")


def flags(runs: Iterable[dict]) -> dict[str, Flags]:
    """Per method, its done runs' flags. Each run: `method`, `done` (bool), `low_coverage`, `diverged` (1, 0 or
    missing) and `eval_settings` (the ledger's JSON text, for the thresholds named in the note)."""
    out: dict[str, Flags] = {}
    for r in runs:
        if not r.get("done"):
            continue
        f = out.setdefault(str(r["method"]), Flags())
        f.done += 1
        low, div = _one(r.get(col.LOW_COVERAGE)), _one(r.get(col.DIVERGED))
        f.low_coverage += low
        f.diverged += div
        settings = _settings(r.get("eval_settings"))
        if low and "coverage_mark" in settings:
            f.coverage_mark.add(settings["coverage_mark"])
        if div:
            f.diverged_at.add(settings.get("max_ate_rel") or DIVERGED_FLAG_REL)
    return out


def marked(name: str, found: dict[str, Flags]) -> str:
    """A method's name with its marks: `colmap †`."""
    symbol = found[name].symbol if name in found else ""
    return f"{name} {symbol}" if symbol else name


def notes(found: dict[str, Flags]) -> list[str]:
    """What the marks of `found` mean, one line per mark in use ([] where no method is marked)."""
    out = []
    if low := _flagged(found, "low_coverage", "coverage_mark", "the dataset's coverage_mark"):
        share, parts = low
        out.append(
            f"{LOW_COVERAGE} low coverage: done runs with poses for fewer than {share} of the frames their method was "
            f"given ({parts}): their figures are of what they tracked, not of the sequence."
        )
    if div := _flagged(found, "diverged", "diverged_at", "0.5"):
        at, parts = div
        out.append(
            f"{DIVERGED} diverged: done runs whose ATE exceeds {at} of the ground truth's spread (ate_rel; the "
            f"dataset sets no max_ate_rel that would make them failures) ({parts})."
        )
    return out


def _flagged(found: dict[str, Flags], count: str, thresholds: str, default: str) -> tuple[str, str] | None:
    """What a mark's note says of the methods with runs it flags (`count`, a Flags field), or None where it flags
    none: the thresholds their runs were judged by (the Flags field `thresholds`; `default` where none is recorded)
    and each method's flagged runs of its done ones ("colmap 2 of 10, dpvo 1 of 10")."""
    flagged = {m: f for m, f in found.items() if getattr(f, count)}
    if not flagged:
        return None
    at = _shares({v for f in flagged.values() for v in getattr(f, thresholds)}, default)
    return at, ", ".join(f"{m} {getattr(f, count)} of {f.done}" for m, f in flagged.items())


def _shares(values: set, default: str) -> str:
    return " / ".join(f"{v:g}" for v in sorted(values)) if values else default


def _one(v) -> int:
    try:
        return int(v is not None and not (isinstance(v, float) and math.isnan(v)) and float(v) >= 1)
    except (TypeError, ValueError):
        return 0


def _settings(text) -> dict:
    if not isinstance(text, str) or not text:
        return {}
    try:
        value = json.loads(text)
    except ValueError:
        return {}
    return value if isinstance(value, dict) else {}
