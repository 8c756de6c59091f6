"""The names of results, in one place: run states, failure kinds (and which are the method's), evaluation
statuses, the metric and resource columns of the ledger and results.csv, and their labels in tables and figures.

Every part of slamrun that writes or reads results (ledger, evaluation, batch evaluation, export, summaries,
statistics, report, command line) takes its names from here, so a new metric or failure kind is added once.
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


# TUM-Mono's figures as the benchmark defines them (docs/tum-mono.md)
# the metrics a spec, a layout or `evaluate --metric` may name; how each is computed: core/metric_table.py
METRIC_NAMES = ("tum-mono", "ate", "rpe", "kitti")
TUM_MONO_METRICS = ("e_t", "e_r", "e_s", "e_align", "e_start", "e_end", "e_rmse")
# ATE, RPE and KITTI's segment errors as a campaign records them
ATE_COLUMNS = ("ate_rmse", "ate_mean", "ate_median", "ate_max", "ate_rel")  # ate_rel: RMSE / the path's spread
RPE_COLUMNS = ("rpe_t_rmse", "rpe_r_rmse", "rpe_pairs", "rpe_interval")  # the interval as text: "1 s"
TEXT_METRIC_COLUMNS = ("rpe_interval",)
KITTI_COLUMNS = ("kitti_t_pct", "kitti_r_deg_m")

METRIC_COLUMNS = (
    *TUM_MONO_METRICS[:3],
    "e_s_sym",
    *TUM_MONO_METRICS[3:],
    "n_poses",
    *ATE_COLUMNS,
    *RPE_COLUMNS,
    *KITTI_COLUMNS,
    "coverage",  # share of the frames the method was given (its stride over the view) with a pose
    "coverage_of_sequence",  # share of the sequence's frames with a pose
    "low_coverage",  # 1: coverage under the dataset's coverage_mark (marked in every view)
    "diverged",  # 1: ate_rel over the dataset's max_ate_rel, or over DIVERGED_FLAG_REL where it sets none
)
FLAG_COLUMNS = ("low_coverage", "diverged")  # 0 or 1 (empty where the run has no figure to judge)
RESOURCE_COLUMNS = (
    "wall_s",
    "fps",
    "cpu_mean_pct",
    "cpu_peak_pct",
    "ram_peak_mb",
    "gpu_mem_peak_mb",
    "gpu_util_mean_pct",
    "n_frames",
    "cpu_wait_pct",  # the run's threads' time runnable but waiting for a CPU, % of wall time (100 % = one thread)
    "host_cpu_pressure_pct",  # the share of the run's wall time in which some task on the machine waited for a CPU
    "cpu_wait_own_pct",  # of cpu_wait_pct, the run's own: per declared thread beyond its CPUs, or measured excess
    "runnable_threads",  # its threads runnable on average: (CPU time + CPU wait) / wall time
    "busy_threads",  # the threads its method declares it keeps busy, with its parameters
)

# `slamrun evaluate --metric tum-mono`: the fields of each file's result
EVALUATE_FIELDS = ("status", *TUM_MONO_METRICS, "n_poses")

# The statistics: the study's six (e_s' for scale), then the trajectory metrics of datasets that ask for them
STUDY_METRICS = ("e_t", "e_r", "e_s_sym", "e_start", "e_end", "e_rmse")
TRAJECTORY_STATS_METRICS = ("ate_rmse", "rpe_t_rmse", "rpe_r_rmse", "kitti_t_pct", "kitti_r_deg_m")
# The per-method summary's medians (terminal table, status, report)
SUMMARY_METRICS = ("e_t", "e_r", "e_s_sym", "e_align", "e_rmse", "ate_rmse", "rpe_t_rmse")
# A run's accuracy figure, the first of these its dataset's runs have: TUM-Mono's e_align, else ATE RMSE (the per-run
# views of the report, the live page's box plot); a finished run's progress line goes on to RPE's and KITTI's
MAIN_METRICS = ("e_align", "ate_rmse")

LABELS = {
    # TUM-Mono's ground truth has an arbitrary scale, shared by its two segments: its lengths are in its units
    "e_t": "translation drift e_t (GT units)",
    "e_r": "rotation drift e_r (deg)",
    "e_s": "scale drift e_s (factor)",
    "e_s_sym": "scale drift e_s' (factor)",
    "e_align": "alignment error e_align (GT units)",
    "e_start": "start-segment RMSE (GT units)",
    "e_end": "end-segment RMSE (GT units)",
    "e_rmse": "RMSE, both segments (GT units)",
    "ate_rmse": "ATE RMSE (m)",
    "ate_mean": "ATE mean (m)",
    "ate_median": "ATE median (m)",
    "ate_max": "ATE max (m)",
    "rpe_t_rmse": "RPE translation RMSE (m)",
    "rpe_r_rmse": "RPE rotation RMSE (deg)",
    "rpe_pairs": "RPE pose pairs",
    "rpe_interval": "RPE interval",
    "kitti_t_pct": "KITTI translation error (%)",
    "kitti_r_deg_m": "KITTI rotation error (deg/m)",
    "ate_rel": "ATE / path spread",
    "coverage": "coverage (share of its frames)",
    "coverage_of_sequence": "share of the sequence's frames",
    "cpu_wait_pct": "waiting for a CPU (% of wall time)",
    "host_cpu_pressure_pct": "machine's CPU pressure (%)",
}


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
