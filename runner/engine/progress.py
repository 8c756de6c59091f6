"""A campaign's figures from its ledger rows: counts, failures by kind, ETA, lane occupancy.

Pure: `figures(rows, session, now)` takes the rows of the active plan (dicts as the ledger returns them)
and the session record the campaign keeps in the ledger's meta table. The live display, `slamrun status`
(table, --watch, --json) and the end-of-campaign summary all print these same numbers.
"""

from __future__ import annotations

import statistics
from collections import Counter, defaultdict
from collections.abc import Iterable
from dataclasses import asdict, dataclass, field

from runner.results.summary import tally_rows
from runner.results.vocabulary import is_infra


@dataclass
class Figures:
    campaign: str
    total: int
    done: int
    failed: int  # method failures (a result of the method)
    infra: int  # infrastructure failures (not a result; retried at the next start)
    pending: int
    running: int
    failures: dict[str, int]  # method failure kind -> count
    lanes: int
    elapsed_s: float | None  # of the current (or last) session
    eta_s: float | None
    eta_basis: str  # measured | partly estimated | unknown | -
    occupancy: float | None  # sum of run wall time / (lanes x session time), this session
    active: bool  # a campaign process is running now
    per_group: list[dict] = field(default_factory=list)  # per method and direction

    @property
    def finished(self) -> int:
        return self.done + self.failed + self.infra

    def to_dict(self) -> dict:
        return asdict(self) | {"finished": self.finished}


def eta(left: dict[str, int], walls: dict[str, list[float]], lanes: int) -> tuple[float | None, str]:
    """Seconds until the runs left end: per method, the median wall time of its finished runs times its runs
    left, summed and spread over the lanes. A method with no finished run yet borrows the median of all."""
    todo = {m: n for m, n in left.items() if n > 0}
    if not todo:
        return 0.0, "-"
    every = [w for ws in walls.values() for w in ws]
    if not every:
        return None, "unknown"
    overall = statistics.median(every)
    total = sum(n * (statistics.median(walls[m]) if walls.get(m) else overall) for m, n in todo.items())
    basis = "measured" if all(walls.get(m) for m in todo) else "partly estimated"
    return total / max(lanes, 1), basis


def wall_times(rows: Iterable[dict]) -> dict[str, list[float]]:
    """Per method label, the wall times of its finished runs (method results, not infrastructure failures)."""
    walls: dict[str, list[float]] = defaultdict(list)
    for r in rows:
        if r["state"] in ("done", "failed") and not is_infra(r["state"], r.get("failure")) and r.get("wall_s"):
            walls[r["label"]].append(float(r["wall_s"]))
    return walls


def figures(rows: list[dict], session: dict | None = None, now: float | None = None, campaign: str = "") -> Figures:
    session = session or {}
    lanes = int(session.get("lanes") or 1)
    t = tally_rows(rows)
    # runs left: unfinished, and infrastructure failures (retried at the next start)
    left: dict[str, int] = Counter(
        r["label"] for r in rows if r["state"] in ("pending", "running") or is_infra(r["state"], r.get("failure"))
    )
    eta_s, basis = eta(left, wall_times(rows), lanes)
    started = session.get("runs_from") or session.get("started_at")  # the scheduler's span when known
    ended = session.get("runs_to") or session.get("ended_at")
    elapsed = occupancy = None
    if started:
        end = ended or now
        if end is not None:
            elapsed = max(end - started, 0.0)
            busy = sum(
                float(r["wall_s"])
                for r in rows
                if r.get("wall_s") and r.get("started_at") and r["started_at"] >= started and r["state"] != "running"
            )
            occupancy = busy / (lanes * elapsed) if elapsed > 0 else None
    return Figures(
        campaign=campaign,
        total=len(rows),
        done=t.done,
        failed=t.failed,
        infra=t.infra,
        pending=sum(r["state"] == "pending" for r in rows),
        running=sum(r["state"] == "running" for r in rows),
        failures={k: n for k, n in t.failures.items() if n},
        lanes=lanes,
        elapsed_s=elapsed,
        eta_s=eta_s,
        eta_basis=basis,
        occupancy=occupancy,
        active=bool(session) and not ended,
        per_group=per_group(rows),
    )


def per_group(rows: list[dict]) -> list[dict]:
    """Counts per method label and direction, with the success rate over method results."""
    groups: dict[tuple[str, str], list[dict]] = defaultdict(list)
    for r in rows:
        groups[(r["label"], r["direction"])].append(r)
    out = []
    for (label, direction), group in sorted(groups.items()):
        t = tally_rows(group)
        out.append(
            {
                "method": label,
                "direction": direction,
                "pending": sum(r["state"] == "pending" for r in group),
                "running": sum(r["state"] == "running" for r in group),
                "done": t.done,
                "failed": t.failed,
                "infra": t.infra,
                "success_pct": t.success_pct,
            }
        )
    return out


def duration(seconds: float | None) -> str:
    """1 h 05 min, 12 min, 40 s; '?' when unknown."""
    if seconds is None:
        return "?"
    s = int(round(seconds))
    if s >= 3600:
        return f"{s // 3600} h {s % 3600 // 60:02d} min"
    if s >= 60:
        return f"{s // 60} min {s % 60:02d} s"
    return f"{s} s"


def one_line(f: Figures) -> str:
    """The figures as one plain line (logs, non-terminal output)."""
    kinds = ", ".join(f"{k} {n}" for k, n in f.failures.items())
    parts = [
        f"{f.finished}/{f.total} finished",
        f"done {f.done}",
        f"failed {f.failed}" + (f" ({kinds})" if kinds else ""),
    ]
    if f.infra:
        parts.append(f"infra {f.infra}")
    if f.elapsed_s is not None:
        parts.append(f"elapsed {duration(f.elapsed_s)}")
    if f.finished < f.total:
        parts.append(f"ETA {duration(f.eta_s)}" + (f" ({f.eta_basis})" if f.eta_basis not in ("measured", "-") else ""))
    if f.occupancy is not None:
        parts.append(f"lanes busy {100 * f.occupancy:.0f} %")
    return ", ".join(parts)
