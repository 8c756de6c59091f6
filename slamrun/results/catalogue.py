"""The results catalogue: every metric and resource column of the ledger and results.csv, declared once with its
label (and unit), its SQLite type, the metric that fills it and its roles in the views.

The ledger's schema, the export, the terminal, the live page, the report and the statistics read their columns
from here: a new metric is its function (core/metrics.py), its entry in core/metric_table.py and its columns here.
Light on purpose (no numpy): the command line's help and the spec's schema import it.
"""

from __future__ import annotations

from dataclasses import dataclass

# Roles: where a column is shown or used beyond the ledger and results.csv (every column is in both).
SUMMARY = "summary"  # a per-method median: terminal table, status, report, live page
MAIN = "main"  # a run's accuracy figure: the first of these its dataset's runs have (per-run views, box plot)
PROGRESS = "progress"  # a finished run's line: its main figure, else the first of these it has
STUDY = "study"  # the study's six statistics (e_s' for scale)
STATISTICS = "statistics"  # the trajectory metrics tested where a dataset asks for them
FIGURE = "figure"  # a cumulative figure in the report
FLAG = "flag"  # 0 or 1 (empty where the run has no figure to judge): marked in every view
RESOURCE = "resource"  # what the run cost (the monitor's figures), not what it achieved
DERIVED = "derived"  # computed from the metric's other figures (not one of its own results)


@dataclass(frozen=True)
class Column:
    """One column: `label` names it in tables and figures with its unit; `unit` follows a value in a terminal line;
    `heading` is its shorter name in the resources table (Table 2's layout) where it has one."""

    name: str
    label: str = ""
    type: str = "REAL"  # its SQLite type in the ledger: REAL, INTEGER (counts, 0/1 flags) or TEXT
    metric: str = ""  # the metric that fills it (core/metric_table.py); "" for the evaluation's and monitor's own
    unit: str = ""
    heading: str = ""
    roles: frozenset[str] = frozenset()

    def has(self, role: str) -> bool:
        return role in self.roles


def _c(name: str, label: str = "", *roles: str, **kw) -> Column:
    return Column(name, label or name, roles=frozenset(roles), **kw)


TUM_MONO, ATE, RPE, KITTI = "tum-mono", "ate", "rpe", "kitti"  # the metrics a spec, a layout or evaluate may name
METRIC_NAMES = (TUM_MONO, ATE, RPE, KITTI)
METRIC_TITLES = {TUM_MONO: "TUM-Mono's errors", ATE: "ATE", RPE: "RPE", KITTI: "KITTI's segment errors"}
RPE_UNITS = ("frames", "s", "m", "evo-f", "evo-m")  # RPE's interval: the sequence's frames, seconds, metres; evo's

# The columns code names one by one (the others it reaches through the roles and tuples below)
E_ALIGN, E_S, E_S_SYM, N_POSES = "e_align", "e_s", "e_s_sym", "n_poses"
ATE_RMSE, ATE_REL, COVERAGE, LOW_COVERAGE, DIVERGED = "ate_rmse", "ate_rel", "coverage", "low_coverage", "diverged"
WALL_S, FPS, N_FRAMES, CPU_WAIT_PCT = "wall_s", "fps", "n_frames", "cpu_wait_pct"
RUNNABLE_THREADS, BUSY_THREADS = "runnable_threads", "busy_threads"

# TUM-Mono's ground truth has an arbitrary scale, shared by its two segments: its lengths are in its units
_GT = "(GT units)"
METRIC_CATALOGUE = (
    _c("e_t", f"translation drift e_t {_GT}", SUMMARY, STUDY, FIGURE, metric=TUM_MONO),
    _c("e_r", "rotation drift e_r (deg)", SUMMARY, STUDY, FIGURE, metric=TUM_MONO, unit="deg"),
    _c(E_S, "scale drift e_s (factor)", metric=TUM_MONO),
    _c(E_S_SYM, "scale drift e_s' (factor)", SUMMARY, STUDY, FIGURE, DERIVED, metric=TUM_MONO),
    _c(E_ALIGN, f"alignment error e_align {_GT}", SUMMARY, MAIN, PROGRESS, metric=TUM_MONO),
    _c("e_start", f"start-segment RMSE {_GT}", STUDY, FIGURE, metric=TUM_MONO),
    _c("e_end", f"end-segment RMSE {_GT}", STUDY, FIGURE, metric=TUM_MONO),
    _c("e_rmse", f"RMSE, both segments {_GT}", SUMMARY, STUDY, metric=TUM_MONO),
    _c(N_POSES, type="INTEGER"),
    _c(ATE_RMSE, "ATE RMSE (m)", SUMMARY, MAIN, PROGRESS, STATISTICS, FIGURE, metric=ATE, unit="m"),
    _c("ate_mean", "ATE mean (m)", metric=ATE, unit="m"),
    _c("ate_median", "ATE median (m)", metric=ATE, unit="m"),
    _c("ate_max", "ATE max (m)", metric=ATE, unit="m"),
    # RMSE / the ground truth's RMS spread: README, Metrics, Divergence
    _c(ATE_REL, "ATE / path spread", metric=ATE),
    _c("rpe_t_rmse", "RPE translation RMSE (m)", SUMMARY, PROGRESS, STATISTICS, FIGURE, metric=RPE, unit="m"),
    _c("rpe_r_rmse", "RPE rotation RMSE (deg)", STATISTICS, metric=RPE, unit="deg"),
    _c("rpe_pairs", "RPE pose pairs", metric=RPE, type="INTEGER"),
    _c("rpe_interval", "RPE interval", metric=RPE, type="TEXT"),  # as text: "1 s"
    _c("kitti_t_pct", "KITTI translation error (%)", PROGRESS, STATISTICS, metric=KITTI, unit="%"),
    _c("kitti_r_deg_m", "KITTI rotation error (deg/m)", STATISTICS, metric=KITTI, unit="deg/m"),
    # share of the frames the method was given (its stride over the view) with a pose
    _c(COVERAGE, "coverage (share of its frames)"),
    _c("coverage_of_sequence", "share of the sequence's frames"),  # of the sequence's frames
    _c(LOW_COVERAGE, "", FLAG, type="INTEGER"),  # 1: coverage under the dataset's coverage_mark
    # 1: ate_rel over the dataset's max_ate_rel, or over DIVERGED_FLAG_REL where it sets none
    _c(DIVERGED, "", FLAG, type="INTEGER"),
)
RESOURCE_CATALOGUE = (
    _c(WALL_S, "", RESOURCE, heading="time (s)"),
    _c(FPS, "", RESOURCE, heading="FPS"),
    _c("cpu_mean_pct", "", RESOURCE, heading="CPU mean %"),
    _c("cpu_peak_pct", "", RESOURCE, heading="CPU peak %"),
    _c("ram_peak_mb", "", RESOURCE, heading="RAM peak MB"),
    _c("gpu_mem_peak_mb", "", RESOURCE, heading="GPU mem MB"),
    _c("gpu_util_mean_pct", "", RESOURCE, heading="GPU %"),
    _c(N_FRAMES, "", RESOURCE, type="INTEGER"),
    # the run's threads' time runnable but waiting for a CPU, % of wall time (100 % = one thread)
    _c(CPU_WAIT_PCT, "waiting for a CPU (% of wall time)", RESOURCE, heading="CPU wait %"),
    # the share of the run's wall time in which some task on the machine waited for a CPU
    _c("host_cpu_pressure_pct", "machine's CPU pressure (%)", RESOURCE, heading="machine CPU pressure %"),
    _c("cpu_wait_own_pct", "", RESOURCE),  # of cpu_wait_pct, the run's own: per declared thread beyond its CPUs
    _c(RUNNABLE_THREADS, "", RESOURCE, heading="runnable threads"),  # (CPU time + CPU wait) / wall time
    _c(BUSY_THREADS, "", RESOURCE, heading="declared threads"),  # the threads its method declares it keeps busy
)
CATALOGUE = {c.name: c for c in (*METRIC_CATALOGUE, *RESOURCE_CATALOGUE)}
# Table 2's order (the study's: CPU, GPU, memory, time, FPS), then the contention figures
RESOURCES_TABLE = ("cpu_mean_pct", "cpu_peak_pct", "gpu_util_mean_pct", "gpu_mem_peak_mb", "ram_peak_mb", "wall_s")
RESOURCES_TABLE += ("fps", "cpu_wait_pct", "host_cpu_pressure_pct", "runnable_threads", "busy_threads")


def column(name: str) -> Column:
    return CATALOGUE[name]


def with_role(role: str) -> tuple[str, ...]:
    """The columns with `role`, in the catalogue's order."""
    return tuple(c.name for c in CATALOGUE.values() if c.has(role))


def columns_of(metric: str) -> tuple[str, ...]:
    """The columns `metric` fills, in the catalogue's order."""
    return tuple(c.name for c in CATALOGUE.values() if c.metric == metric)


def label(name: str) -> str:
    """A column's label with its unit; any other name as it is."""
    return CATALOGUE[name].label if name in CATALOGUE else name


def metric_of(name: str) -> str:
    """The metric that fills column `name` ("" for a column no metric fills, or a name not in the catalogue)."""
    return CATALOGUE[name].metric if name in CATALOGUE else ""


def typed(kind: str) -> tuple[str, ...]:
    """The columns of SQLite type `kind`."""
    return tuple(c.name for c in CATALOGUE.values() if c.type == kind)


METRIC_COLUMNS = tuple(c.name for c in METRIC_CATALOGUE)
RESOURCE_COLUMNS = tuple(c.name for c in RESOURCE_CATALOGUE)
TEXT_METRIC_COLUMNS = tuple(c for c in typed("TEXT") if c in METRIC_COLUMNS)
FLAG_COLUMNS = with_role(FLAG)
TUM_MONO_METRICS = tuple(c for c in columns_of(TUM_MONO) if not column(c).has(DERIVED))  # as the benchmark defines
ATE_COLUMNS, RPE_COLUMNS, KITTI_COLUMNS = columns_of(ATE), columns_of(RPE), columns_of(KITTI)
STUDY_METRICS = with_role(STUDY)
TRAJECTORY_STATS_METRICS = with_role(STATISTICS)
SUMMARY_METRICS = with_role(SUMMARY)
MAIN_METRICS = with_role(MAIN)
PROGRESS_METRICS = with_role(PROGRESS)
FIGURE_METRICS = with_role(FIGURE)
LABELS = {c.name: c.label for c in CATALOGUE.values() if c.label != c.name}
NON_NEGATIVE = frozenset(c.name for c in CATALOGUE.values() if c.metric)  # a metric's figures are never negative
