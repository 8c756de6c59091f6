"""A campaign's figures from its ledger rows: counts, failures by kind, ETA, lane occupancy.

Pure: `figures(rows, session, now)` takes the rows of the active plan (dicts as the ledger returns them)
and the session record the campaign keeps in the ledger's meta table. The live display, `slamrun status`
(table, --watch, --json) and the end-of-campaign summary all print these same numbers.
"""

from __future__ import annotations

import bisect
from collections import Counter, defaultdict
from collections.abc import Iterable
from dataclasses import asdict, dataclass, field

from slamrun.results.catalogue import CPU_WAIT_PCT, WALL_S
from slamrun.results.vocabulary import METHOD_FAILURES, is_infra, played


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


RunGroup = tuple[str, str]  # (method label, "dataset/sequence"): runs whose wall times are alike


def run_group(row: dict) -> RunGroup:
    return row["method"], f"{row.get('dataset') or ''}/{row.get('sequence') or ''}"


class WallTimes:
    """The wall times of finished runs per (method, sequence), kept sorted per group, per method and overall, so
    a median is read without sorting: the ETA of a 10,000-run campaign costs per finished run what a 10-run
    one does (a run is added or removed in O(log n) comparisons and one memmove)."""

    def __init__(self, walls: dict[RunGroup, list[float]] | None = None):
        self.by_group: dict[RunGroup, list[float]] = defaultdict(list)
        self.by_method: dict[str, list[float]] = defaultdict(list)
        self.every: list[float] = []
        for group, ws in (walls or {}).items():
            for w in ws:
                self.add(group, w)

    def add(self, group: RunGroup, wall_s: float) -> None:
        for values in (self.by_group[group], self.by_method[group[0]], self.every):
            bisect.insort(values, wall_s)

    def remove(self, group: RunGroup, wall_s: float) -> None:
        for values in (self.by_group[group], self.by_method[group[0]], self.every):
            del values[bisect.bisect_left(values, wall_s)]

    def typical(self, group: RunGroup) -> float:
        """The group's median wall time; that method's median over its other sequences when the group has no
        finished run yet; else the median of all."""
        for values in (self.by_group.get(group), self.by_method.get(group[0]), self.every):
            if values:
                return _median(values)
        raise ValueError("no finished run")

    def __bool__(self) -> bool:
        return bool(self.every)


def _median(ordered: list[float]) -> float:
    n = len(ordered)
    return ordered[n // 2] if n % 2 else (ordered[n // 2 - 1] + ordered[n // 2]) / 2


def eta(
    left: dict[RunGroup, int],
    walls: dict[RunGroup, list[float]] | WallTimes,
    lanes: int,
    overhead_s: float = 0.0,
    running: Iterable[tuple[RunGroup, float]] = (),
) -> tuple[float | None, str]:
    """Seconds until the runs left end: per method and sequence, the median wall time of its finished runs plus
    the runner's own time per run on a lane (`overhead_s`: starting, collecting, waiting for a view), times its
    runs left, summed and spread over the lanes. A sequence a method has not finished yet borrows that method's
    median over its other sequences; a method with no finished run, the median of all, or the longest time one of
    its `running` runs (group, seconds so far) has run when that is longer: they show its runs take at least that.
    A running run counts for what it has still to go (its typical time less its seconds so far, at least nothing),
    so the ETA falls as runs progress and does not jump when a slow method's first run ends."""
    todo = {g: n for g, n in left.items() if n > 0}
    if not todo:
        return 0.0, "-"
    times = walls if isinstance(walls, WallTimes) else WallTimes(walls)
    if not times:
        return None, "unknown"
    running = list(running)
    at_least: dict[str, float] = defaultdict(float)  # a method with no finished run: its longest running run so far
    for (label, _), so_far in running:
        if not times.by_method.get(label):
            at_least[label] = max(at_least[label], so_far)

    def typical(g: RunGroup) -> float:
        return max(times.typical(g), at_least.get(g[0], 0.0))

    total = sum(n * (typical(g) + overhead_s) for g, n in todo.items())
    total -= sum(min(so_far, typical(g)) for g, so_far in running if todo.get(g))
    basis = "measured" if all(times.by_group.get(g) for g in todo) else "partly estimated"
    return max(total, 0.0) / max(lanes, 1), basis


def overhead_per_run(busy_s: float, runs: int, lanes: int, elapsed_s: float | None) -> float:
    """The lanes' time per run that is not the runs' own wall time, measured over a session: (lanes x elapsed -
    runs' wall time) / runs; 0 until a few runs have finished."""
    if not elapsed_s or runs < 3:
        return 0.0
    return max(lanes * elapsed_s - busy_s, 0.0) / runs


def wall_times(rows: Iterable[dict]) -> dict[RunGroup, list[float]]:
    """Per method label and sequence, the wall times of its finished runs (method results, not infrastructure
    failures)."""
    walls: dict[RunGroup, list[float]] = defaultdict(list)
    for r in rows:
        if r["status"] in ("done", "failed") and not is_infra(r["status"], r.get("failure")) and r.get(WALL_S):
            walls[run_group(r)].append(float(r[WALL_S]))
    return walls


def figures(rows: list[dict], session: dict | None = None, now: float | None = None, campaign: str = "") -> Figures:
    """The figures of a set of ledger rows (`slamrun status`, the end of a campaign); the live view keeps a
    Tracker instead and applies each run's change to it."""
    return Tracker(rows, session, campaign).figures(now)


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


def _category(state: str, failure: str | None) -> str:
    return "infra" if is_infra(state, failure) else state


class Tracker:
    """A campaign's figures kept current from its runs' changes at a constant cost per run, never rescanning the
    ledger: the live view of a 10,000-run plan costs per finished run what that of a 10-run plan does.

    Built from the ledger's rows once; `update(key, status=..., ...)` applies one run's change (its event); the
    figures equal `figures(rows, session, now)` over the same rows."""

    def __init__(self, rows: Iterable[dict], session: dict | None = None, campaign: str = ""):
        self.session = session or {}
        self.campaign = campaign
        self.lanes = int(self.session.get("lanes") or 1)
        self.started = self.session.get("runs_from") or self.session.get("started_at")
        self.rows: dict[str, dict] = {}
        self.groups: dict[tuple[str, str], Counter] = defaultdict(Counter)
        self.failures: Counter = Counter()
        self.waits: dict[tuple[str, str], list[float]] = defaultdict(lambda: [0.0, 0])  # CPU wait %: sum, runs
        self.walls = WallTimes()
        self.left: Counter = Counter()  # (label, sequence) -> runs left
        self.running: dict = {}  # key -> (group, started_at) of the runs running now (a lane's worth each)
        self.busy = 0.0
        self.session_runs = 0
        self.unknown = 0
        for i, r in enumerate(rows):
            row = {k: r.get(k) for k in ("method", "direction", "status", "failure", WALL_S, "started_at")}
            row[CPU_WAIT_PCT] = r.get(CPU_WAIT_PCT)
            row["direction"] = played(row["direction"], r.get("perturbation"), r.get("level"))
            row["group"], row["key"] = run_group(r), r.get("key", i)
            self.rows[row["key"]] = row
            self._count(row, +1)

    def update(self, key: str, **changes) -> None:
        """One run's new state (and failure, wall_s, started_at when known); unknown keys are ignored."""
        row = self.rows.get(key)
        if row is None:
            self.unknown += 1  # a run of a plan newer than these rows: the caller reads the ledger again
            return
        self._count(row, -1)
        row.update({k: v for k, v in changes.items() if k in row})
        if changes.get("status") in ("pending", "running") and "failure" not in changes:
            row["failure"] = None
        self._count(row, +1)

    def _count(self, row: dict, sign: int) -> None:
        cat = _category(row["status"], row["failure"])
        self.groups[(row["method"], row["direction"])][cat] += sign
        if cat == "failed":
            self.failures[row["failure"]] += sign
        if cat in ("done", "failed") and row.get(CPU_WAIT_PCT) is not None:
            wait = self.waits[(row["method"], row["direction"])]
            wait[0] += sign * float(row[CPU_WAIT_PCT])
            wait[1] += sign
        group = row["group"]
        if cat in ("pending", "running", "infra"):
            self.left[group] += sign
        if cat == "running":
            if sign > 0:
                self.running[row["key"]] = (group, row["started_at"])
            else:
                self.running.pop(row["key"], None)
        if cat in ("done", "failed") and row[WALL_S]:
            if sign > 0:
                self.walls.add(group, float(row[WALL_S]))
            else:
                self.walls.remove(group, float(row[WALL_S]))
        finished = cat in ("done", "failed", "infra")
        if finished and self.started and row["started_at"] and row["started_at"] >= self.started:
            self.busy += sign * float(row[WALL_S] or 0.0)
            self.session_runs += sign

    def _mean_wait(self, label: str, direction: str) -> float | None:
        """The mean CPU wait (% of wall time) of the group's finished runs, where they recorded one."""
        total, n = self.waits.get((label, direction), (0.0, 0))
        return total / n if n > 0 else None

    def figures(self, now: float | None = None) -> Figures:
        totals: Counter = Counter()
        per = []
        for (label, direction), c in sorted(self.groups.items()):
            totals.update(c)
            if sum(c.values()) == 0:
                continue
            results = c["done"] + c["failed"]
            per.append(
                {
                    "method": label,
                    "direction": direction,
                    "pending": c["pending"],
                    "running": c["running"],
                    "done": c["done"],
                    "failed": c["failed"],
                    "infra": c["infra"],
                    "success_pct": 100.0 * c["done"] / results if results else None,
                    CPU_WAIT_PCT: self._mean_wait(label, direction),
                }
            )
        ended = self.session.get("runs_to") or self.session.get("ended_at")
        elapsed = occupancy = None
        overhead = 0.0
        if self.started:
            end = ended or now
            if end is not None:
                elapsed = max(end - self.started, 0.0)
                occupancy = self.busy / (self.lanes * elapsed) if elapsed > 0 else None
                overhead = overhead_per_run(self.busy, self.session_runs, self.lanes, elapsed)
        so_far = [(g, max(now - t0, 0.0)) for g, t0 in self.running.values() if t0 and now is not None]
        eta_s, basis = eta(self.left, self.walls, self.lanes, overhead, so_far)
        kinds = [k for k in METHOD_FAILURES if self.failures[k]] + sorted(
            k for k in self.failures if k not in METHOD_FAILURES and self.failures[k]
        )
        return Figures(
            campaign=self.campaign,
            total=len(self.rows),
            done=totals["done"],
            failed=totals["failed"],
            infra=totals["infra"],
            pending=totals["pending"],
            running=totals["running"],
            failures={k: self.failures[k] for k in kinds},
            lanes=self.lanes,
            elapsed_s=elapsed,
            eta_s=eta_s,
            eta_basis=basis,
            occupancy=occupancy,
            active=bool(self.session) and not ended,
            per_group=per,
        )
