"""Ticks of a log axis that a reader can read values off, one rule for the report's figures and the live page."""

from __future__ import annotations

import math
from collections.abc import Iterable


def log_steps(lo: float, hi: float) -> tuple[float, ...]:
    """The leading digits of the labelled ticks of a log axis from lo to hi: 1, 2 and 5 of each decade where it
    spans three decades or less (at least three labels over one decade), else 1 (each decade)."""
    decades = math.log10(hi / lo) if lo > 0 and hi > lo else 0.0
    return (1.0, 2.0, 5.0) if decades <= 3 else (1.0,)


def log_ticks(values: Iterable[float]) -> list[float]:
    """The labelled ticks of a log axis over the positive, finite `values`, each a whole value (0.002, never a
    bare 2 whose decade is written elsewhere): from the tick at or below the least value to the one at or above the
    greatest, so that values closer together than two ticks (0.030 to 0.043) still have a tick at each end; [] when
    no value is positive."""
    v = [x for x in values if x > 0 and math.isfinite(x)]
    if not v:
        return []
    least, greatest = min(v), max(v)
    lo = math.floor(math.log10(least))
    hi = max(math.ceil(math.log10(greatest)), lo + 1)
    every = [float(f"{s * 10.0**d:.1g}") for d in range(lo, hi + 1) for s in log_steps(least, greatest)]
    below = max(t for t in every if t <= least)
    above = min((t for t in every if t >= greatest and t > below), default=every[-1])
    return [t for t in every if below <= t <= above]
