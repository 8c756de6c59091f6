"""The one tally of a group of runs that every summary uses (the terminal table, `slamrun status`, the report,
the statistics' counts): infrastructure failures and unfinished runs are left out of every rate."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

from slamrun.results.vocabulary import CONTENDED, INFRA_FAILURES, METHOD_FAILURES, EvalStatus


@dataclass
class Tally:
    runs: int = 0
    done: int = 0
    failed: int = 0  # the method's failures
    infra: int = 0  # infrastructure failures (retried, no result), contended runs among them
    contended: int = 0  # of those, runs lost while their threads waited for a CPU (the machine's load)
    pending: int = 0  # pending or running
    evaluated: int = 0  # done, with metrics
    not_evaluable: int = 0  # done, without metrics
    failures: dict[str, int] = field(default_factory=lambda: dict.fromkeys(METHOD_FAILURES, 0))

    @property
    def results(self) -> int:
        """Runs that are a result of the method: done or failed by it."""
        return self.done + self.failed

    @property
    def success_pct(self) -> float | None:
        return 100.0 * self.done / self.results if self.results else None

    @property
    def failure_pct(self) -> float | None:
        return 100.0 * self.failed / self.results if self.results else None


def tally(states: Iterable[tuple[str, str | None, str | None]]) -> Tally:
    """Counts of (state, failure, eval_status) triples."""
    t = Tally()
    for state, failure, eval_status in states:
        t.runs += 1
        if state == "done":
            t.done += 1
            if eval_status == EvalStatus.ok.value:
                t.evaluated += 1
            else:
                t.not_evaluable += 1
        elif state == "failed":
            if failure in INFRA_FAILURES:
                t.infra += 1
                t.contended += failure == CONTENDED
            else:
                t.failed += 1
                if failure:
                    t.failures[failure] = t.failures.get(failure, 0) + 1
        else:
            t.pending += 1
    return t
