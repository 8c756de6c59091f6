"""The one metric table: every metric a spec, a layout or `slamrun evaluate --metric` may name and how it is
computed. The spec's schema, the layouts' defaults, `slamrun evaluate`, batch evaluation and a campaign's per-run
evaluation (`campaign_figures`) all read it; a new metric is one entry here (its function in metrics.py, its
columns in results/catalogue.py)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from slamrun.core import metrics
from slamrun.core.evaluation import ASSOCIATION_TOLERANCE_S, TumMonoResult, tum_mono, tum_mono_file, tum_mono_many
from slamrun.core.trajectory import Trajectory
from slamrun.errors import MetricError
from slamrun.results.catalogue import (
    ATE,
    KITTI,
    METRIC_NAMES,
    N_POSES,
    RPE,
    TUM_MONO,
    TUM_MONO_METRICS,
    columns_of,
)
from slamrun.results.vocabulary import EvalStatus

NO_PAIRS = "no_pairs"  # a metric the path is too short for (RPE's interval, KITTI's 100 m): among others, only noted


class Unevaluated(MetricError):
    """A metric that judges the estimate itself (TUM-Mono's: empty, NaN, unassociated, incomplete): its status is
    the run's eval_status."""

    def __init__(self, status: EvalStatus, detail: str):
        super().__init__(f"evaluation {status.value}: {detail}")
        self.status = status


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
    """A metric: `result`, its full result (what `slamrun evaluate` prints, `to_dict()`), or a MetricError saying why
    not (`Unevaluated` where the estimate itself is at fault); `fields`, the campaign's figures from that result
    (its columns in the catalogue); `preset`, figures known before it is computed; `charged`, whether its failure
    (other than a path too short for it) makes a run's evaluation incomplete. `file_result` judges a FILE where it
    differs from a run (with `many`, many files at once), `file_fields` the figures its file result always shows."""

    name: str
    result: Callable[[Trajectory, Trajectory, Context], object]
    fields: Callable[[object], dict]
    preset: Callable[[Context], dict] = lambda ctx: {}
    charged: bool = True
    file_result: Callable[[Trajectory, Trajectory], object] | None = None
    many: Callable[[Trajectory, list[Trajectory]], list] | None = None
    file_fields: tuple[str, ...] = ()

    @property
    def columns(self) -> tuple[str, ...]:
        """The results.csv columns it fills."""
        return columns_of(self.name)

    def of_file(self, gt: Trajectory, traj: Trajectory, ctx: Context) -> dict:
        """`slamrun evaluate`'s result of one file: its status, n_poses and figures, or why none."""
        if self.file_result is not None:
            return self.file_dict(self.file_result(gt, traj))
        try:
            res = self.result(gt, traj, ctx)
        except MetricError as exc:
            status = NO_PAIRS if isinstance(exc, metrics.NoPairs) else "failed"
            return {"status": status, N_POSES: len(traj), "detail": str(exc)}
        return {"status": "ok", N_POSES: len(traj), **res.to_dict()}

    def file_dict(self, res) -> dict:
        """A `file_result` as `slamrun evaluate` prints it: its status, `file_fields`, why not where not ok."""
        d = res.to_dict()
        detail = {"detail": d["detail"]} if d["status"] != "ok" and d["detail"] else {}
        return {k: d.get(k) for k in ("status", *self.file_fields)} | detail


def _tum_mono(gt: Trajectory, est: Trajectory, ctx: Context) -> TumMonoResult:
    """TUM-Mono's figures of a run (docs/tum-mono.md), or the status that stops them."""
    ev = tum_mono(gt, est)
    if ev.status is not EvalStatus.ok:
        raise Unevaluated(ev.status, ev.detail)
    return ev


METRICS: dict[str, Metric] = {
    m.name: m
    for m in (
        Metric(
            TUM_MONO,
            _tum_mono,
            lambda r: {k: getattr(r, k) for k in TUM_MONO_METRICS} | {"e_s_sym": r.e_s_sym},
            file_result=tum_mono_file,  # a file that holds a NaN row fails, as the benchmark judges it
            many=tum_mono_many,
            file_fields=(*TUM_MONO_METRICS, N_POSES),
        ),
        Metric(
            ATE,
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
            RPE,
            lambda gt, est, c: metrics.rpe(gt, est, c.delta, c.delta_unit, c.alignment, c.tolerance_s, c.frame_times),
            lambda r: {"rpe_t_rmse": r.translation.rmse, "rpe_r_rmse": r.rotation_deg.rmse, "rpe_pairs": r.pairs},
            preset=lambda c: {"rpe_interval": str(metrics.RpeInterval(c.delta, c.delta_unit))},
        ),
        Metric(
            KITTI,
            lambda gt, est, c: metrics.kitti(gt, est, c.alignment, tolerance_s=c.tolerance_s),
            lambda r: {"kitti_t_pct": r.t_pct, "kitti_r_deg_m": r.r_deg_per_m},
            charged=False,  # a path under KITTI's shortest segment (100 m) is the data's limit: only noted
        ),
    )
}
NAMES = tuple(METRICS)
if NAMES != METRIC_NAMES:  # the light list the command line and the spec's schema offer, without numpy
    raise ImportError(f"core/metric_table.py has {NAMES}, results/catalogue.py METRIC_NAMES {METRIC_NAMES}")


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
    are at `frame_times`) and eval_status, and why a metric is missing; the metrics in the table's order. A metric
    that judges the estimate (TUM-Mono's) gives its status; ATE/RPE that cannot be computed make the evaluation
    incomplete; a path shorter than RPE's interval or KITTI's 100 m is the data's limit, only noted (coverage says
    how much of the sequence was tracked)."""
    values: dict = {}
    status, notes = EvalStatus.ok, []
    ctx = Context(alignment, ASSOCIATION_TOLERANCE_S, rpe.delta, rpe.unit, frame_times)
    for m in sorted((metric(name) for name in set(wanted)), key=lambda m: NAMES.index(m.name)):
        values.update(m.preset(ctx))
        try:
            values.update(m.fields(m.result(gt, traj, ctx)))
        except Unevaluated as exc:
            notes.append(str(exc))
            status = exc.status if status in (EvalStatus.ok, EvalStatus.incomplete) else status
        except MetricError as exc:
            notes.append(f"{m.name}: {exc}")
            if m.charged and not isinstance(exc, metrics.NoPairs) and status is EvalStatus.ok:
                status = EvalStatus.incomplete
    values["eval_status"] = status.value
    return values, "; ".join(notes)
