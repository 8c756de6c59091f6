"""The live ETA (`slamrun status`, the progress line, the live page: one Tracker) on a campaign whose methods differ
in pace, replayed second by second: three methods of 4, 12 and 40 s a run, 2 sequences x 2 directions x 3 trials
each, 2 lanes, runs taken in the plan's order (trials outermost), so the slow method starts with no timing of its
own. The replay feeds the Tracker exactly the rows a ledger holds at each second (a run's start, its end and wall
time); it measures the formula, not the machine, so its figures are the same on every machine and every run.

Printed: the ETA's error against the time that really remained at 10, 25 and 50 % of the runs finished (at 10 % only
the fast method has finished a run: nothing yet tells the others' pace, so no target there), and the largest factor
between two readings one second apart while more than 30 s remain (the issue's: 1 min 16 s, then 8 min 44 s)."""

from __future__ import annotations

import heapq
from collections.abc import Callable

from slamrun.engine.progress import Tracker

PACE_S = {"fast": 4.0, "medium": 12.0, "slow": 40.0}
SEQUENCES = ("seq_a", "seq_b")
DIRECTIONS = ("forward", "backward")
TRIALS = 3
LANES = 2


def planned() -> list[dict]:
    """The campaign's rows in the plan's order (trial, method, sequence, direction), each with the wall time it
    will take: the method's pace, +-10 % by sequence, direction and trial (deterministic)."""
    rows = []
    for trial in range(TRIALS):
        for mi, (label, pace) in enumerate(PACE_S.items()):
            for si, seq in enumerate(SEQUENCES):
                for di, direction in enumerate(DIRECTIONS):
                    wobble = 1.0 + 0.1 * (((mi * 7 + si * 5 + di * 3 + trial * 11) % 5) - 2) / 2
                    rows.append(
                        {
                            "key": f"{label}/{seq}/{direction}/{trial}",
                            "method": label,
                            "dataset": "d",
                            "sequence": seq,
                            "direction": direction,
                            "status": "pending",
                            "failure": None,
                            "wall_s": None,
                            "started_at": None,
                            "takes": pace * wobble,
                        }
                    )
    return rows


def replay(rows: list[dict]) -> tuple[list[tuple[float, int, float | None]], float]:
    """Each second of the campaign: (time, runs finished, the Tracker's ETA); and the time the last run ended."""
    starts: list[tuple[float, int]] = []  # (end time, row index) of the running runs
    queue = list(range(len(rows)))
    t, finished, readings = 0.0, 0, []
    session = {"lanes": LANES, "started_at": 0.0}

    def start_runs(now: float) -> None:
        while queue and len(starts) < LANES:
            i = queue.pop(0)
            rows[i].update(status="running", started_at=now)
            heapq.heappush(starts, (now + rows[i]["takes"], i))

    start_runs(0.0)
    while starts or queue:
        while starts and starts[0][0] <= t:
            end, i = heapq.heappop(starts)
            rows[i].update(status="done", wall_s=rows[i]["takes"])
            finished += 1
            start_runs(end)
        fresh = [{k: v for k, v in r.items() if k != "takes"} for r in rows]
        readings.append((t, finished, Tracker(fresh, session, "eta").figures(now=t).eta_s))
        t += 1.0
    last_end = max(r["started_at"] + r["takes"] for r in rows)
    return readings, last_end


def bench_eta(report: Callable[[str, str, str], None]) -> None:
    rows = planned()
    readings, end = replay(rows)
    total = len(rows)
    paces = ", ".join(f"{k} {v:.0f} s" for k, v in PACE_S.items())
    print(f"eta: a replayed campaign of {total} runs ({paces}), {LANES} lanes")
    for share in (0.10, 0.25, 0.50):
        t, _, said = next(r for r in readings if r[1] >= share * total and r[2] is not None)
        real = end - t
        report(f"ETA at {share:.0%} finished (at {t:.0f} s)", f"{said:.0f} s", "-")
        target = "-" if share < 0.25 else "<= 25 %"
        report("  time that really remained; error", f"{real:.0f} s; {100 * abs(said - real) / real:.0f} %", target)
    jumps = [
        max(b / a, a / b)
        for (_, _, a), (tb, _, b) in zip(readings, readings[1:], strict=False)
        if a and b and end - tb > 30.0  # the last seconds: any change is a large factor of little
    ]
    report("largest factor between two readings 1 s apart", f"{max(jumps):.2f}x", "< 1.5x")
