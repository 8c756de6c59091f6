"""What every bench shares: the figures' report (printed with their targets) and pinning to one core."""

from __future__ import annotations

import os
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS: list[tuple[str, str, str]] = []


def report(name: str, value: str, target: str) -> None:
    RESULTS.append((name, value, target))
    print(f"  {name:<58} {value:>22}   target: {target}", flush=True)


def one_core() -> None:
    os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
