"""The one metric table: every metric a spec, a layout or `slamrun evaluate --metric` may name, the results.csv columns
it fills, and how it is computed. The spec's schema, the layouts' defaults, `slamrun evaluate`, batch evaluation and a
campaign's per-run evaluation (`campaign_figures`) all read it; a new metric is one entry here (its function in
metrics.py, its columns in results/vocabulary.py)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from slamrun.core import metrics
from slamrun.core.evaluation import ASSOCIATION_TOLERANCE_S, tum_mono
from slamrun.core.trajectory import Trajectory
from slamrun.errors import MetricError
from slamrun.results.vocabulary import (
    ATE_COLUMNS,
    KITTI_COLUMNS,
    METRIC_NAMES,
    RPE_COLUMNS,
    TUM_MONO_METRICS,
    EvalStatus,
)

TUM_MONO = "tum-mono"


@dataclass(frozen=True)
class Context:
    """How a metric is computed: the alignment, the association tolerance, RPE's interval and the sequence's frame
    times (RPE in frames counts them)."""

    alignment: str = "sim3"
    tolerance_s: float = ASSOCIATION_TOLERANCE_S
    delta: float = 1.0  # RPE's interval (checked by metrics.rpe, so another metric never fails for it)
    delta_unit: str = "s"
    frame_times: np.ndarray | None = None


@dataclass(frozen=True)
class Metric:
    """A metric: its columns in results.csv; `result`, its full result (what `slamrun evaluate` prints, `to_dict()`);
    `fields`, the campaign's figures from that result; `preset`, figures known before it is computed; `charged`,
    whether its failure (other than a path too short for it) makes a run's evaluation incomplete."""

    name: str
    columns: tuple[str, ...]
    result: Callable[[Trajectory, Trajectory, Context], object] | None
    fields: Callable[[object], dict] | None
    preset: Callable[[Context], dict] = lambda ctx: {}
    charged: bool = True


METRICS: dict[str, Metric] = {
    m.name: m
    for m in (
        # TUM-Mono's figures decide a run's eval_status themselves (campaign_figures); files: evaluation.tum_mono_file
        Metric(TUM_MONO, (*TUM_MONO_METRICS[:3], "e_s_sym", *TUM_MONO_METRICS[3:]), None, None),
        Metric(
            "ate",
            ATE_COLUMNS,
            lambda gt, est, c: metrics.ate(gt, est, c.alignment, c.tolerance_s),
            lambda r: {
                "ate_rmse": r.translation.rmse,
                "ate_mean": r.translation.mean,
                "ate_median": r.translation.median,
                "ate_max": r.translation.max,
                "ate_rel": r.relative,
            },
        ),
        Metric(
            "rpe",
            RPE_COLUMNS,
            lambda gt, est, c: metrics.rpe(gt, est, c.delta, c.delta_unit, c.alignment, c.tolerance_s, c.frame_times),
            lambda r: {"rpe_t_rmse": r.translation.rmse, "rpe_r_rmse": r.rotation_deg.rmse, "rpe_pairs": r.pairs},
            preset=lambda c: {"rpe_interval": str(metrics.RpeInterval(c.delta, c.delta_unit))},
        ),
        Metric(
            "kitti",
            KITTI_COLUMNS,
            lambda gt, est, c: metrics.kitti(gt, est, c.alignment, tolerance_s=c.tolerance_s),
            lambda r: {"kitti_t_pct": r.t_pct, "kitti_r_deg_m": r.r_deg_per_m},
            charged=False,  # a path under KITTI's shortest segment (100 m) is the data's limit: only noted
        ),
    )
}
NAMES = tuple(METRICS)
if NAMES != METRIC_NAMES:  # the light list the command line and the spec's schema offer, without numpy
    raise ImportError(f"core/metric_table.py has {NAMES}, results/vocabulary.py METRIC_NAMES {METRIC_NAMES}")


def metric(name: str) -> Metric:
    try:
        return METRICS[name]
    except KeyError:
        raise MetricError(f"unknown metric {name!r}; known: {', '.join(NAMES)}") from None


def campaign_figures(
    gt: Trajectory,
    traj: Trajectory,
    wanted: tuple[str, ...],
    alignment: str,
    rpe: metrics.RpeInterval = metrics.RpeInterval(),
    frame_times: np.ndarray | None = None,
) -> tuple[dict, str]:
    """A finished run's metrics (the dataset's `metrics:`, RPE at the interval `rpe` of the sequence whose frames
    are at `frame_times`) and eval_status, and why a metric is missing. TUM-Mono's figures or ATE/RPE that cannot
    be computed make the evaluation incomplete; a path shorter than RPE's interval or KITTI's 100 m is the data's
    limit, only noted (coverage says how much of the sequence was tracked)."""
    values: dict = {}
    status, notes = EvalStatus.ok, []
    if TUM_MONO in wanted:
        ev = tum_mono(gt, traj)
        status = ev.status
        if ev.status is EvalStatus.ok:
            values.update({k: getattr(ev, k) for k in TUM_MONO_METRICS} | {"e_s_sym": ev.e_s_sym})
        else:
            notes.append(f"evaluation {ev.status.value}: {ev.detail}")
    ctx = Context(alignment, ASSOCIATION_TOLERANCE_S, rpe.delta, rpe.unit, frame_times)
    for name in (m for m in wanted if m != TUM_MONO):
        m = metric(name)
        values.update(m.preset(ctx))
        try:
            values.update(m.fields(m.result(gt, traj, ctx)))
        except MetricError as exc:
            notes.append(f"{name}: {exc}")
            if m.charged and not isinstance(exc, metrics.NoPairs) and status is EvalStatus.ok:
                status = EvalStatus.incomplete
    values["eval_status"] = status.value
    return values, "; ".join(notes)
