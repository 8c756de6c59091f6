"""A finished run's figures from its trajectory, and the failure they decide: its coverage of the frames the method
was given (and of the sequence), the dataset's metrics, the divergence and coverage flags, and the evaluation
settings they were made with. The same code evaluates a run when it finishes, an imported trajectory, and a finished
run again when its dataset's evaluation settings changed (engine/reevaluate.py: no method runs again)."""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass

import numpy as np

from slamrun.core import metrics
from slamrun.core.metric_table import campaign_figures
from slamrun.core.metrics import RpeInterval
from slamrun.core.trajectory import Trajectory
from slamrun.datasets.perturb import BASELINE, Perturbation, kept_frames
from slamrun.datasets.view import Direction
from slamrun.results import catalogue as col
from slamrun.results.vocabulary import (
    DIVERGED,
    DIVERGED_FLAG_REL,
    UNDER_MIN_COVERAGE,
    EvalStatus,
)

# Raised whenever the figures a trajectory gives change (a run recorded with another version is evaluated again from
# its trajectory at the next campaign or report): 2, RPE at exactly its interval, coverage of the frames given,
# ate_rel and its flags.
EVALUATION_VERSION = 2
LOW_COVERAGE = 0.5  # default coverage_mark: runs with poses for fewer of the frames they were given are marked
# A path whose farthest pose from its first lies this many times beyond its poses' count times their median step
# (the farthest a path of such steps could go) has exploded: numbers, not motion (a method's diverged optimisation)
EXPLODED = 1e6


@dataclass(frozen=True)
class EvalSettings:
    """What a run's figures depend on besides its trajectory: the dataset's metrics, alignment, RPE interval, the
    coverage threshold and mark, the divergence threshold, and the evaluation code's version."""

    metrics: tuple[str, ...] = ("tum-mono",)
    alignment: str = "sim3"
    rpe: RpeInterval = RpeInterval()
    min_coverage: float | None = None
    max_ate_rel: float | None = None
    coverage_mark: float = LOW_COVERAGE
    version: int = EVALUATION_VERSION

    def text(self) -> str:
        """The settings as the ledger records them (one JSON object, keys sorted): equal text, equal figures."""
        d = asdict(self) | {"metrics": list(self.metrics), "rpe": str(self.rpe)}
        return json.dumps(d, sort_keys=True)


@dataclass(frozen=True)
class Frames:
    """A run's frames as original times, increasing: the sequence's, the view's (without a frame_drop view's dropped
    frames) and those the method was given (its own stride over the view)."""

    sequence: np.ndarray
    view: np.ndarray
    given: np.ndarray


def run_frames(
    sequence_times: np.ndarray, perturbation: Perturbation, direction: Direction, given: np.ndarray | None = None
) -> Frames:
    """The frames of a run on a view of a sequence whose frames are at `sequence_times` (increasing): `given`, the
    indices of the view's frames in the order the view plays them that the method takes (None: all)."""
    seq = np.asarray(sequence_times, float)
    kept = kept_frames(len(seq), perturbation or BASELINE)
    played = kept if direction is Direction.forward else kept[::-1]
    chosen = played if given is None else played[np.asarray(given, int)]
    return Frames(seq, seq[kept], np.sort(seq[chosen]))


def evaluate_trajectory(
    traj: Trajectory, groundtruth: Trajectory | None, frames: Frames, settings: EvalSettings
) -> tuple[dict, str]:
    """A trajectory's figures and why a metric has none: poses, coverage of the frames given and of the sequence, the
    dataset's metrics (without ground truth: none), the flags (diverged, low_coverage) and the settings used."""
    values: dict = {
        col.N_POSES: len(traj),
        col.COVERAGE: metrics.coverage(traj, frames.given),
        "coverage_of_sequence": metrics.coverage(traj, frames.sequence),
        "eval_settings": settings.text(),
    }
    detail = ""
    if (why := exploded(traj)) is not None:
        values["exploded"] = why  # no metric can use it: no figure is computed (settle makes it the method's failure)
    elif groundtruth is not None:
        figures, detail = campaign_figures(
            groundtruth, traj, settings.metrics, settings.alignment, settings.rpe, frames.view
        )
        values.update(figures)
    rel = values.get(col.ATE_REL)
    flag_at = settings.max_ate_rel or DIVERGED_FLAG_REL
    values[col.DIVERGED] = int(rel > flag_at) if _finite(rel) else None
    values[col.LOW_COVERAGE] = (
        int(values[col.COVERAGE] < settings.coverage_mark) if _finite(values[col.COVERAGE]) else None
    )
    return values, detail


def settle(values: dict, failure: str | None, message: str | None, detail: str, settings: EvalSettings) -> None:
    """The run's failure and message in `values`, from the failure its process left (`failure`, `message`: the
    method's own, or None) and its figures: too few poses to evaluate (lost), a loss it recovered from, too little
    coverage of its frames (lost, under min_coverage), a path beyond max_ate_rel (diverged)."""
    message = message or detail or None
    if failure is None and values.get("exploded"):
        failure, message = DIVERGED, values["exploded"]
    if failure is None and values.get("eval_status") == EvalStatus.incomplete.value:
        failure = "lost"  # too few poses in a segment to evaluate: the method did not track the sequence
        message = f"too few poses to evaluate ({message})"
    if failure is None and values.get("eval_status") == EvalStatus.nan.value:
        failure = "lost"  # poses that give no figure (all of a segment at one point): no success without figures
        message = f"its poses give no figure ({message})"
    if failure == "lost?":  # lost, then relocalised: only a failure when the result cannot be evaluated
        failure = None if values.get("eval_status") == EvalStatus.ok.value else "lost"
    share = values.get(col.COVERAGE)
    if failure is None and settings.min_coverage and _finite(share) and share < settings.min_coverage:
        failure = "lost"  # it tracked too little of what it was given for its accuracy to be compared
        message = f"poses for {100 * share:.0f} % of its frames, {UNDER_MIN_COVERAGE} {settings.min_coverage:g}"
    rel = values.get(col.ATE_REL)
    if failure is None and settings.max_ate_rel and _finite(rel) and rel > settings.max_ate_rel:
        failure = DIVERGED  # its path bears no likeness to the ground truth's: a tracking failure
        message = (
            f"ATE {values[col.ATE_RMSE]:.4g} is {rel:.2f} of the ground truth's spread, over the dataset's max_ate_rel "
            f"{settings.max_ate_rel:g}"
        )
    values.update(failure=failure, message=message)


def exploded(traj: Trajectory) -> str | None:
    """Why a trajectory's numbers exploded (its farthest pose from its first beyond EXPLODED times its poses' count
    times their median step, or not finite in arithmetic), or None. Steps are measured per coordinate (no squares:
    1e155 does not overflow here)."""
    p = traj.positions
    if len(p) < 3:
        return None
    with np.errstate(all="ignore"):
        steps = np.abs(np.diff(p, axis=0)).max(axis=1)
        farthest = float(np.abs(p - p[0]).max())
    moving = steps[steps > 0]
    if not len(moving):
        return None
    median = float(np.median(moving))
    if np.isfinite(farthest) and farthest <= EXPLODED * median * len(p):
        return None
    return (
        f"its poses explode: {farthest:.3g} from its first pose, over {EXPLODED:g} times what {len(p)} steps of its "
        f"median step ({median:.3g}) could reach: numbers, not motion; no figure is computed"
    )


def _finite(v) -> bool:
    return isinstance(v, int | float) and math.isfinite(v)
