"""The names of results, in one place: run states, failure kinds (and which are the method's), evaluation
statuses, how a run was played. The metric and resource columns are declared in results/catalogue.py.

Every part of slamrun that writes or reads results (ledger, evaluation, batch evaluation, export, summaries,
statistics, report, command line) takes its names from here, so a new failure kind is added once.
"""

from __future__ import annotations

from enum import StrEnum

STATES = ("pending", "running", "done", "failed")

# What a method did: data for the statistics and the success rate.
METHOD_FAILURES = (
    "not_initialized",  # never produced a pose
    "lost",  # stopped tracking (or too few poses to evaluate)
    "no_output",  # ended without a readable trajectory
    "crashed",  # exited abnormally
    "timeout",  # killed at the run's timeout
    "oom",  # killed out of memory
    "bad_timestamps",  # poses at times that are not the sequence's frame times
    "output_limit",  # wrote more than max_output_mb, or filled the disk
    "diverged",  # its ATE beyond the dataset's max_ate_rel: its path bears no likeness to the ground truth's
)
INFRA = "infra"  # the machine's fault: retried, never counted in a rate
# lost or never initialised while its threads waited for a CPU longer than the spec's contention_pct: the machine's
# load, not the method, is the likelier cause; retried and counted apart, as infrastructure failures are
CONTENDED = "contended"
CONTENTION_PCT = 15.0  # the threshold of cpu_wait_pct measured to separate the two (README: the numbers that chose it)
OWN_WAIT_PER_THREAD_PCT = 60.0  # the wait a run causes itself per busy thread beyond its lane's CPUs: ORB-SLAM3 (3
# threads, 2 CPUs) waited 32.5-58.4 % of its wall time in 24 runs on an idle machine, 90-154 % beside two CPU hogs
CONTENDABLE = ("lost", "not_initialized")  # the failures a starved real-time method shows
INFRA_FAILURES = (INFRA, CONTENDED)
UNDER_MIN_COVERAGE = "under the dataset's min_coverage"  # in the message of a run lost for its coverage
DIVERGED = "diverged"
# ATE RMSE relative to the ground truth's RMS distance from its centroid over the run's poses (ate_rel: 1 = no better
# than collapsing the trajectory to one point; 1 - ate_rel^2 is the share of the path's variance the aligned estimate
# explains). A run over this is flagged diverged in results.csv and every view, also where the dataset sets no
# max_ate_rel (which makes it a failure): README, Metrics, Divergence.
DIVERGED_FLAG_REL = 0.5
FAILURES = (*METHOD_FAILURES, *INFRA_FAILURES)


IMPORTED = "imported"  # the `method` of runs imported from published files (kept whatever a spec plans)


def is_infra(state: str | None, failure: str | None) -> bool:
    """A run that failed for infrastructure reasons (not a result of the method)."""
    return state == "failed" and failure in INFRA_FAILURES


class EvalStatus(StrEnum):
    """Why a finished trajectory has (ok) or lacks metrics."""

    ok = "ok"
    empty = "empty"  # no pose at all
    nan = "nan"  # a NaN or infinite value in the estimate
    unassociated = "unassociated"  # a pose without a ground-truth row within the tolerance
    incomplete = "incomplete"  # too few poses for a metric (a TUM-Mono segment, ATE, RPE)


NONE = "none"  # the baseline perturbation: the ordinary view (slamrun.datasets.perturb)


def level_text(level: float) -> str:
    """A level as names and keys write it: `5`, `0.5` (six significant digits), or every digit where those would
    make two levels one name (4.000001 and 4.000002 are not both `4`)."""
    short = f"{float(level):g}"
    return short if float(short) == float(level) else repr(float(level))


def played(direction: str, kind: str | None, level: float | None) -> str:
    """How a run's sequence was played, as status and the report name it: `forward`, `forward+gaussian_noise-5`."""
    if not kind or kind == NONE or level is None:
        return direction
    return f"{direction}+{kind}-{level_text(level)}"
