"""The TUM-Mono benchmark's metrics (Engel et al. 2016), plus ATE and RPE. Pure functions, no I/O.

See docs: association within 1 ms, start/end segments split by ground-truth rows, a Sim(3) alignment
per segment, and the drift figures e_t, e_r, e_s, e_align, e_start, e_end, e_rmse derived from them.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from enum import StrEnum

import numpy as np

from runner.alignment import align_sim3, rmse, rotation_angle_deg
from runner.trajectory import Trajectory

ASSOCIATION_TOLERANCE_S = 1e-3
MIN_SEGMENT_POSES = 3  # a Sim(3) alignment needs at least three poses to be determined

METRIC_NAMES = ("e_t", "e_r", "e_s", "e_align", "e_start", "e_end", "e_rmse")


class EvalStatus(StrEnum):
    ok = "ok"
    empty = "empty"  # no pose at all
    nan = "nan"  # a NaN or infinite value in the estimate
    unassociated = "unassociated"  # a pose without a ground-truth row within 1 ms
    incomplete = "incomplete"  # a segment with fewer than MIN_SEGMENT_POSES poses


@dataclass(frozen=True)
class TumMonoResult:
    """One trajectory's TUM-Mono figures. Every metric is NaN unless status is ok."""

    status: EvalStatus
    e_t: float = math.nan
    e_r: float = math.nan  # degrees
    e_s: float = math.nan  # s_start / s_end, a factor
    e_align: float = math.nan
    e_start: float = math.nan
    e_end: float = math.nan
    e_rmse: float = math.nan
    n_poses: int = 0
    detail: str = ""

    @property
    def e_s_sym(self) -> float:
        """e_s' = max(e_s, 1/e_s) >= 1, the scale figure used in medians and plots."""
        return max(self.e_s, 1.0 / self.e_s) if self.status is EvalStatus.ok else math.nan

    def to_dict(self) -> dict:
        """JSON-ready: metrics are null unless ok."""
        d = asdict(self)
        d["status"] = self.status.value
        ok = self.status is EvalStatus.ok
        for k in METRIC_NAMES:
            d[k] = d[k] if ok else None
        d["e_s_sym"] = self.e_s_sym if ok else None
        return d


def _failed(status: EvalStatus, n: int, detail: str) -> TumMonoResult:
    return TumMonoResult(status=status, n_poses=n, detail=detail)


def associate(gt_times: np.ndarray, est_times: np.ndarray, tol: float = ASSOCIATION_TOLERANCE_S) -> np.ndarray:
    """For each estimated timestamp the index of the nearest ground-truth row within `tol`, else -1.

    `gt_times` must be sorted increasingly.
    """
    idx = np.searchsorted(gt_times, est_times)
    lo = np.clip(idx - 1, 0, len(gt_times) - 1)
    hi = np.clip(idx, 0, len(gt_times) - 1)
    nearest = np.where(np.abs(gt_times[lo] - est_times) <= np.abs(gt_times[hi] - est_times), lo, hi)
    ok = np.abs(gt_times[nearest] - est_times) <= tol
    return np.where(ok, nearest, -1)


def tum_mono(gt: Trajectory, est: Trajectory) -> TumMonoResult:
    """Evaluate one estimated trajectory against a TUM-Mono groundtruthSync (NaN rows allowed)."""
    n = len(est)
    if n == 0:
        return _failed(EvalStatus.empty, 0, "no pose in the estimate")
    if not (np.isfinite(est.positions).all() and np.isfinite(est.quaternions).all()):
        return _failed(EvalStatus.nan, n, "the estimate holds NaN or infinite values")
    gt_t = gt.timestamps
    match = associate(gt_t, est.timestamps)
    if np.any(match < 0):
        bad = est.timestamps[np.flatnonzero(match < 0)[0]]
        return _failed(
            EvalStatus.unassociated, n, f"{np.count_nonzero(match < 0)} poses (first t={bad!r}) have no GT within 1 ms"
        )
    n_gt = len(gt_t)
    start_lo, start_hi = gt_t[0], gt_t[n_gt // 2 - 1]
    end_lo, end_hi = gt_t[(n_gt + 1) // 2 - 1], gt_t[-1]
    gt_pos = gt.positions[match]
    valid = np.isfinite(gt_pos).all(axis=1)
    t = est.timestamps
    in_start = valid & (t >= start_lo) & (t <= start_hi)
    in_end = valid & (t >= end_lo) & (t <= end_hi)
    n_s, n_e = int(in_start.sum()), int(in_end.sum())
    if n_s < MIN_SEGMENT_POSES or n_e < MIN_SEGMENT_POSES:
        return _failed(EvalStatus.incomplete, n, f"segment poses: start {n_s}, end {n_e}; need >= {MIN_SEGMENT_POSES}")

    p = est.positions
    s_start = align_sim3(p[in_start], gt_pos[in_start])
    s_end = align_sim3(p[in_end], gt_pos[in_end])
    e_start = rmse(s_start.apply(p[in_start]), gt_pos[in_start])
    e_end = rmse(s_end.apply(p[in_end]), gt_pos[in_end])

    drift = s_end.matrix() @ np.linalg.inv(s_start.matrix())
    e_t = float(np.linalg.norm(drift[:3, 3]))
    e_r = rotation_angle_deg(s_end.rotation @ s_start.rotation.T)
    e_s = s_start.scale / s_end.scale
    e_align = rmse(s_end.apply(p), s_start.apply(p))

    both = in_start | in_end
    s_both = align_sim3(p[both], gt_pos[both])
    e_rmse = rmse(s_both.apply(p[both]), gt_pos[both])
    values = (e_t, e_r, e_s, e_align, e_start, e_end, e_rmse)
    if not all(math.isfinite(v) for v in values):
        return _failed(EvalStatus.nan, n, "degenerate alignment (all poses of a segment at one point)")
    return TumMonoResult(EvalStatus.ok, *values, n_poses=n)


@dataclass(frozen=True)
class AteResult:
    status: EvalStatus
    rmse: float = math.nan
    scale: float = math.nan
    n_poses: int = 0


def ate(gt: Trajectory, est: Trajectory) -> AteResult:
    """Absolute trajectory error: RMSE after one Sim(3) alignment over all associated poses with GT."""
    n = len(est)
    if n == 0:
        return AteResult(EvalStatus.empty)
    if not np.isfinite(est.positions).all():
        return AteResult(EvalStatus.nan, n_poses=n)
    match = associate(gt.timestamps, est.timestamps)
    use = match >= 0
    use[use] = np.isfinite(gt.positions[match[use]]).all(axis=1)
    if use.sum() < MIN_SEGMENT_POSES:
        return AteResult(EvalStatus.unassociated if not (match >= 0).any() else EvalStatus.incomplete, n_poses=n)
    a, b = est.positions[use], gt.positions[match[use]]
    sim = align_sim3(a, b)
    return AteResult(EvalStatus.ok, rmse(sim.apply(a), b), sim.scale, int(use.sum()))


@dataclass(frozen=True)
class RpeResult:
    status: EvalStatus
    trans_rmse: float = math.nan
    rot_rmse_deg: float = math.nan
    n_pairs: int = 0


def rpe(gt: Trajectory, est: Trajectory, delta: int = 1) -> RpeResult:
    """Relative pose error over pairs `delta` associated poses apart (Sturm et al. 2012).

    The estimate's scale is first corrected with the ATE Sim(3) scale (monocular methods have none).
    """
    match = associate(gt.timestamps, est.timestamps) if len(est) else np.zeros(0, int)
    use = np.flatnonzero(match >= 0)
    if len(est) == 0:
        return RpeResult(EvalStatus.empty)
    use = use[np.isfinite(gt.positions[match[use]]).all(axis=1)]
    if len(use) <= delta:
        return RpeResult(EvalStatus.incomplete)
    scale = align_sim3(est.positions[use], gt.positions[match[use]]).scale
    r_est, r_gt = est.rotations()[use], gt.rotations()[match[use]]
    p_est, p_gt = scale * est.positions[use], gt.positions[match[use]]

    def relative(r: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        r_rel = np.einsum("nji,njk->nik", r[:-delta], r[delta:])
        p_rel = np.einsum("nji,nj->ni", r[:-delta], p[delta:] - p[:-delta])
        return r_rel, p_rel

    re, pe = relative(r_est, p_est)
    rg, pg = relative(r_gt, p_gt)
    # error = inv(gt_rel) * est_rel
    r_err = np.einsum("nji,njk->nik", rg, re)
    p_err = np.einsum("nji,nj->ni", rg, pe - pg)
    cos = (np.trace(r_err, axis1=1, axis2=2) - 1.0) / 2.0
    axis = np.stack(
        [r_err[:, 2, 1] - r_err[:, 1, 2], r_err[:, 0, 2] - r_err[:, 2, 0], r_err[:, 1, 0] - r_err[:, 0, 1]], 1
    )
    angle = np.arctan2(np.linalg.norm(axis, axis=1) / 2.0, cos)
    return RpeResult(
        EvalStatus.ok,
        float(np.sqrt(np.mean(np.sum(p_err**2, axis=1)))),
        float(np.degrees(np.sqrt(np.mean(angle**2)))),
        len(re),
    )
