"""Trajectory metrics beyond TUM-Mono: ATE, RPE and KITTI's segment errors, with the association and the
alignment they need. Pure functions on Trajectory values.

Definitions follow the reference tools: ATE and RPE as evo computes them (Grupp 2017; Sturm et al. 2012 for
the RPE's error pose), KITTI's segment errors as the KITTI odometry development kit's evaluate_odometry.cpp
(Geiger et al. 2012). tests/test_metrics.py checks them against evo's Python API on real files.

Association is evo's sync.associate_trajectories on the rows as the files hold them (`Trajectory.rows_as_read`):
a repeated timestamp's every row, a file's order where its timestamps go backward, so such files give evo's figures
(tests/test_association.py, on fr2/desk's ground truth, which repeats a timestamp).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from slamrun.core.alignment import Sim3, align_sim3
from slamrun.core.nearest import nearest
from slamrun.core.trajectory import Trajectory, quat_to_rotmat, rotmat_to_quat
from slamrun.errors import MetricError
from slamrun.results.catalogue import RPE_UNITS

DEFAULT_TOLERANCE_S = 0.02  # TUM RGB-D's evaluate_ate.py, and evo's 0.01 doubled: frames at 30 Hz are 0.033 s apart
KITTI_LENGTHS_M = (100, 200, 300, 400, 500, 600, 700, 800)
KITTI_STEP_FRAMES = 10


class NoPairs(MetricError):
    """The trajectory is too short for the metric's interval: no RPE pair, no KITTI segment (the data's limit)."""


# ----------------------------------------------------------------------------------------- association


@dataclass(frozen=True)
class Pairs:
    """Ground truth and estimate reduced to their associated poses, in the order of the one with fewer rows."""

    gt: Trajectory
    est: Trajectory


def associate(gt: Trajectory, est: Trajectory, tolerance_s: float = DEFAULT_TOLERANCE_S) -> Pairs:
    """evo's sync.associate_trajectories(gt, est) (nearest_time, max_diff = `tolerance_s`), on the rows as the
    files hold them (`Trajectory.rows_as_read`: a repeated timestamp's every row, in the file's order) and the
    ground truth's finite rows: each row of the one with fewer rows (the estimate at equal counts), in its order,
    is paired with the row of the other that `matching_time_indices` finds within `tolerance_s` (a row of the
    longer one may pair several times). A tolerance of 0 pairs exactly equal times only. MetricError when no
    pose pairs."""
    gt, est = _finite(gt.rows_as_read()), est.rows_as_read()
    gt_t, est_t = gt.timestamps, est.timestamps
    if not len(est_t) or not len(gt_t):
        raise MetricError(f"no pose to pair: the estimate has {len(est_t)}, the ground truth {len(gt_t)}")
    est_shorter = len(est_t) <= len(gt_t)
    short_t, long_t = (est_t, gt_t) if est_shorter else (gt_t, est_t)
    short_ids, long_ids = matching_time_indices(short_t, long_t, tolerance_s)
    if not len(short_ids):
        raise MetricError(
            f"the estimate and the ground truth share no timestamp within {tolerance_s} s (estimate "
            f"{est_t.min():.6f}..{est_t.max():.6f}, ground truth {gt_t.min():.6f}..{gt_t.max():.6f}); wrong file "
            "or time base?"
        )
    est_ids, gt_ids = (short_ids, long_ids) if est_shorter else (long_ids, short_ids)
    return Pairs(_take(gt, gt_ids), _take(est, est_ids))


def matching_time_indices(short_t: np.ndarray, long_t: np.ndarray, tolerance_s: float) -> tuple[np.ndarray, np.ndarray]:
    """evo's sync.matching_time_indices(short_t, long_t, max_diff=tolerance_s): for each time of `short_t`, in
    order, the row of `long_t` nearest to it, where within `tolerance_s`; the indices of both. Where `long_t`
    never decreases, evo's binary search: of two rows at the same distance the earlier, and of rows at one
    repeated time the last, but the first when the time is approached from below. Otherwise evo's linear
    search: the first row in `long_t`'s order at the smallest distance."""
    if np.all(np.diff(long_t) >= 0):
        best, keep = _binary_search(short_t, long_t, tolerance_s)
    else:
        best, distance = _first_nearest(short_t, long_t)
        keep = distance <= tolerance_s
    return np.flatnonzero(keep), best[keep]


def _binary_search(short_t: np.ndarray, long_t: np.ndarray, tolerance_s: float) -> tuple[np.ndarray, np.ndarray]:
    """evo's binary-search branch, vectorised: the row of sorted `long_t` matched to each time, and whether any is."""
    idx = np.minimum(np.searchsorted(long_t, short_t, side="right"), len(long_t) - 1)
    upper = long_t[idx] - short_t
    lower = np.where(idx > 0, short_t - long_t[np.maximum(idx - 1, 0)], np.inf)
    take_upper = (upper <= tolerance_s) & (upper < lower)
    take_lower = ~take_upper & (lower <= tolerance_s) & (lower <= upper)
    inside = ~((short_t < long_t[0] - tolerance_s) | (short_t > long_t[-1] + tolerance_s))
    return np.where(take_upper, idx, idx - 1), inside & (take_upper | take_lower)


def _first_nearest(short_t: np.ndarray, long_t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """evo's linear search (argmin of |long_t - t|: the first row at the smallest distance) for each time of
    `short_t`, by sorting instead of a pass over `long_t` per time: the row and its distance."""
    order = np.argsort(long_t, kind="stable")  # equal times keep their order: a time's first row leads its group
    times = long_t[order]
    starts = np.flatnonzero(np.concatenate(([True], times[1:] != times[:-1])))
    distinct, first_row = times[starts], order[starts]
    k = np.searchsorted(distinct, short_t)
    lo, hi = np.maximum(k - 1, 0), np.minimum(k, len(distinct) - 1)
    d_lo, d_hi = np.abs(distinct[lo] - short_t), np.abs(distinct[hi] - short_t)
    take_hi = (d_hi < d_lo) | ((d_hi == d_lo) & (first_row[hi] < first_row[lo]))
    return np.where(take_hi, first_row[hi], first_row[lo]), np.where(take_hi, d_hi, d_lo)


def poses_at(gt: Trajectory, times: np.ndarray, tolerance_s: float) -> Trajectory:
    """The ground truth's pose that evo pairs with each of `times` (a trajectory at those times with fewer rows
    than `gt`, associated with it: `matching_time_indices` on `gt`'s rows as read), put at that time; NaN rows
    where none is within `tolerance_s`."""
    times = np.asarray(times, float)
    rows = gt.rows_as_read()
    pos, quat = np.full((len(times), 3), np.nan), np.full((len(times), 4), np.nan)
    if len(rows) and len(times):
        ids, best = matching_time_indices(times, rows.timestamps, tolerance_s)
        pos[ids], quat[ids] = rows.positions[best], rows.quaternions[best]
    return Trajectory(times, pos, quat)


def _take(traj: Trajectory, ids: np.ndarray) -> Trajectory:
    return Trajectory(traj.timestamps[ids], traj.positions[ids], traj.quaternions[ids])


def coverage(est: Trajectory, frame_times: np.ndarray, tolerance_s: float = 1e-3) -> float:
    """The share of frames with a pose (a pose within `tolerance_s` of the frame's time)."""
    if not len(frame_times):
        return math.nan
    if not len(est):
        return 0.0
    near = nearest(np.sort(est.timestamps), frame_times)[1]
    return float(np.count_nonzero(near <= tolerance_s)) / len(frame_times)


# ------------------------------------------------------------------------------------------- alignment


@dataclass(frozen=True)
class Alignment:
    """How an estimate is aligned to the ground truth before a metric: `sim3` (monocular: scale unknown),
    `se3` (stereo, RGB-D, VIO), `none`; over every associated pose, or over the first `first_n` only."""

    kind: str = "sim3"
    first_n: int | None = None

    @classmethod
    def parse(cls, text: str) -> Alignment:
        """'sim3', 'se3', 'none', 'first:N' (Sim(3) over the first N poses) or 'se3:first:N'."""
        parts = text.strip().lower().split(":")
        kind = parts[0] if parts[0] in ("sim3", "se3", "none") else "sim3"
        rest = parts[1:] if parts[0] in ("sim3", "se3", "none") else parts
        if rest and (len(rest) != 2 or rest[0] != "first" or not rest[1].isdigit() or int(rest[1]) < 3):
            raise MetricError(f"alignment {text!r}: expected sim3, se3, none, first:N or se3:first:N (N >= 3)")
        if kind == "none" and rest:
            raise MetricError(f"alignment {text!r}: 'none' takes no first:N")
        return cls(kind, int(rest[1]) if rest else None)

    def __str__(self) -> str:
        return self.kind + (f":first:{self.first_n}" if self.first_n else "")

    def fit(self, est_positions: np.ndarray, gt_positions: np.ndarray) -> Sim3:
        """The transformation taking the estimate onto the ground truth."""
        if self.kind == "none":
            return Sim3(np.eye(3), np.zeros(3), 1.0)
        n = len(est_positions) if self.first_n is None else self.first_n
        if n > len(est_positions):  # never a fit over fewer poses than asked for
            raise MetricError(
                f"alignment over the first {n} poses, but {len(est_positions)} pair with the ground truth: "
                f"give N <= {len(est_positions)}"
            )
        if n < 3:
            raise MetricError(f"{n} associated pose(s): an alignment needs at least 3")
        src, dst = est_positions[:n], gt_positions[:n]
        sim = align_sim3(src, dst)
        if self.kind == "se3":
            return Sim3(sim.rotation, dst.mean(axis=0) - sim.rotation @ src.mean(axis=0), 1.0)
        return sim


def aligned(est: Trajectory, sim: Sim3) -> np.ndarray:
    """The estimate's poses as 4x4 matrices after `sim` (rotation composed, positions mapped)."""
    poses = np.zeros((len(est), 4, 4))
    poses[:, :3, :3] = sim.rotation @ est.rotations()
    poses[:, :3, 3] = sim.apply(est.positions)
    poses[:, 3, 3] = 1.0
    return poses


def matrices(traj: Trajectory) -> np.ndarray:
    poses = np.zeros((len(traj), 4, 4))
    poses[:, :3, :3] = traj.rotations()
    poses[:, :3, 3] = traj.positions
    poses[:, 3, 3] = 1.0
    return poses


# ------------------------------------------------------------------------------------------ statistics


@dataclass(frozen=True)
class ErrorStats:
    rmse: float
    mean: float
    median: float
    std: float
    min: float
    max: float
    n: int

    @classmethod
    def of(cls, errors: np.ndarray) -> ErrorStats:
        if not len(errors):
            raise MetricError("no error value to summarise")
        e = np.asarray(errors, float)
        return cls(
            rmse=float(np.sqrt(np.mean(e * e))),
            mean=float(np.mean(e)),
            median=float(np.median(e)),
            std=float(np.std(e)),
            min=float(np.min(e)),
            max=float(np.max(e)),
            n=len(e),
        )


# ------------------------------------------------------------------------------------------------- ATE


@dataclass(frozen=True)
class AteResult:
    """Absolute trajectory error: position errors (m) after the alignment."""

    translation: ErrorStats
    scale: float  # of the alignment (1 unless sim3)
    alignment: str
    errors: np.ndarray  # per associated pose, in the estimate's order
    gt_spread: float = math.nan  # the associated ground truth's RMS distance from its centroid
    transform: Sim3 | None = None  # the alignment's: the estimate onto the ground truth (the views draw it so)

    @property
    def relative(self) -> float:
        """The RMSE relative to the ground truth's spread (`ate_rel`): 1 is the error of the whole estimate collapsed
        to one point (its ATE under Sim(3) is at most about this); 1 - ate_rel^2 is the share of the path's variance
        the aligned estimate explains. NaN where the ground truth does not move."""
        return self.translation.rmse / self.gt_spread if self.gt_spread > 0 else math.nan

    def to_dict(self) -> dict:
        flat = {"metric": "ate", "alignment": self.alignment, "scale": self.scale, **_flat("ate", self.translation)}
        return flat | {"ate_rel": None if math.isnan(self.relative) else self.relative}


def ate(
    gt: Trajectory, est: Trajectory, alignment: Alignment | str = "sim3", tolerance_s: float = DEFAULT_TOLERANCE_S
) -> AteResult:
    """ATE of `est` against `gt` (evo's APE w.r.t. the translation part, after its Umeyama alignment)."""
    alignment = Alignment.parse(alignment) if isinstance(alignment, str) else alignment
    pairs = associate(gt, est, tolerance_s)
    sim = alignment.fit(pairs.est.positions, pairs.gt.positions)
    errors = np.linalg.norm(sim.apply(pairs.est.positions) - pairs.gt.positions, axis=1)
    centred = pairs.gt.positions - pairs.gt.positions.mean(axis=0)
    spread = math.sqrt(float(np.einsum("ij,ij->", centred, centred)) / len(centred))
    return AteResult(ErrorStats.of(errors), float(sim.scale), str(alignment), errors, spread, sim)


# ------------------------------------------------------------------------------------------------- RPE

SEQUENCE_UNITS = RPE_UNITS[:3]  # frames, s, m: an interval of the sequence, whatever the estimate's rate
EVO_UNITS = RPE_UNITS[3:]  # evo_rpe's --delta_unit f and m: steps of the estimate's own associated poses
# s and m: each pose is paired with the pose at exactly its time (path) + delta, interpolated between the estimate's
# two poses around that point where none lies on it; both must lie within RPE_BRACKET x delta of it (within
# [axis + delta/2, axis + 3 delta/2]), so that a hole in the track wider than delta gives no pair through it and no
# interpolation spans more than the interval it measures.
RPE_BRACKET = 0.5
RPE_M_ROUNDING = 1e-9  # m: an estimate pose "at" the point, relative to the distance (the path's rounding)


@dataclass(frozen=True)
class RpeInterval:
    """How far apart RPE's pose pairs are. `frames`: the sequence's frames (pairs of estimate poses whose frames are
    exactly `delta` frames apart, by the frames' times); `s`: seconds (TUM RGB-D's per-second drift); `m`: metres
    travelled along the ground truth. `evo-f` and `evo-m` are evo's own (`--delta_unit f` / `m`): every `delta`-th
    associated estimate pose, or each time the aligned estimate has travelled `delta` metres, so that an estimate
    written every 5th frame gets an interval five times as long."""

    delta: float = 1.0
    unit: str = "s"

    def __post_init__(self) -> None:
        if self.unit not in RPE_UNITS:
            raise MetricError(f"RPE delta unit {self.unit!r}: expected one of {', '.join(RPE_UNITS)}")
        whole = self.unit in ("frames", "evo-f")
        if not math.isfinite(self.delta) or self.delta <= 0 or (whole and float(self.delta) != int(self.delta)):
            what = "whole number of frames" if whole else "seconds" if self.unit == "s" else "distance in metres"
            raise MetricError(f"RPE delta {self.delta}: expected a positive {what}")

    def __str__(self) -> str:
        return f"{self.delta:g} {self.unit}"


@dataclass(frozen=True)
class RpeResult:
    """Relative pose error over pose pairs `delta` `unit` apart: translation (m), rotation (deg), and the number
    of pairs it was computed over."""

    translation: ErrorStats
    rotation_deg: ErrorStats
    delta: float
    unit: str  # one of RPE_UNITS
    alignment: str
    pairs: int = 0

    @property
    def interval(self) -> str:
        return str(RpeInterval(self.delta, self.unit))

    def to_dict(self) -> dict:
        return {
            "metric": "rpe",
            "alignment": self.alignment,
            "delta": self.delta,
            "delta_unit": self.unit,
            "rpe_pairs": self.pairs,
            **_flat("rpe_t", self.translation),
            **_flat("rpe_r", self.rotation_deg),
        }


def rpe(
    gt: Trajectory,
    est: Trajectory,
    delta: float = 1,
    unit: str = "s",
    alignment: Alignment | str = "sim3",
    tolerance_s: float = DEFAULT_TOLERANCE_S,
    frame_times: np.ndarray | None = None,
) -> RpeResult:
    """RPE of `est` against `gt`: align the estimate (over every pose paired with the ground truth), choose pose
    pairs (i, j) `delta` `unit` apart (see RpeInterval; `frames` needs the sequence's `frame_times`), and take the
    error pose E = (Q_i^-1 Q_j)^-1 (P_i^-1 P_j): |t(E)| and the angle of R(E).

    With a sequence unit every pose starts a pair where a partner lies at its interval (pairs overlap, as TUM RGB-D's
    evaluate_rpe.py with a fixed delta); the estimate's poses are taken in time order, one per timestamp. With `s` and
    `m` the partner is the pose at exactly the pose's time (path along the ground truth) + delta: the estimate's pose
    there (within `tolerance_s` for `s`, to rounding for `m`), else the aligned estimate and the ground truth both
    interpolated there between the estimate's two poses around it (the same weight; positions linearly, rotations by
    slerp), where both lie within RPE_BRACKET x delta of it; so an estimate's RPE does not depend on the rate it was
    written at. With an evo unit the pairs are evo's: consecutive, on the associated rows as the files hold them."""
    interval = RpeInterval(float(delta), unit)
    alignment = Alignment.parse(alignment) if isinstance(alignment, str) else alignment
    if unit in EVO_UNITS:
        pairs = associate(gt, est, tolerance_s)
        est_p, gt_p = pairs.est, pairs.gt
    else:
        if unit == "frames" and frame_times is None:
            raise MetricError("RPE in frames counts the sequence's frames: give the frame times (--times FILE)")
        at = poses_at(gt, est.timestamps, tolerance_s)
        keep = np.flatnonzero(np.isfinite(at.positions).all(axis=1) & np.isfinite(at.quaternions).all(axis=1))
        if not len(keep):
            raise MetricError(f"none of the estimate's {len(est)} poses has a ground-truth pose within {tolerance_s} s")
        est_p, gt_p = _take(est, keep), _take(at, keep)
    sim = alignment.fit(est_p.positions, gt_p.positions)
    p = aligned(est_p, sim)
    q = matrices(gt_p)
    if unit in ("s", "m"):  # the pose at exactly delta further, interpolated where the estimate has none there
        if unit == "s":
            axis, snap = est_p.timestamps, min(tolerance_s, RPE_BRACKET * float(delta))
        else:
            axis, snap = _path_along(_finite(gt), est_p.timestamps), None
        i, a, b, w = _pairs_by_axis(axis, float(delta), snap)
        q_j, p_j = _interpolated(q, a, b, w), _interpolated(p, a, b, w)
    else:
        if unit == "evo-f":
            i, j = _pairs_by_index(len(p), int(delta))
        elif unit == "evo-m":
            i, j = _pairs_by_path(p[:, :3, 3], float(delta))
        else:
            i, j = _pairs_by_frames(est_p.timestamps, np.asarray(frame_times, float), int(delta), tolerance_s)
        q_j, p_j = q[j], p[j]
    if not len(i):
        raise NoPairs(f"no pose pair {interval} apart among {len(p)} poses paired with the ground truth")
    q_rel = _inverse(q[i]) @ q_j
    p_rel = _inverse(p[i]) @ p_j
    err = _inverse(q_rel) @ p_rel
    trans = np.linalg.norm(err[:, :3, 3], axis=1)
    rot = _angles_deg(err[:, :3, :3])
    return RpeResult(ErrorStats.of(trans), ErrorStats.of(rot), float(delta), unit, str(alignment), len(i))


def _pairs_by_frames(
    times: np.ndarray, frame_times: np.ndarray, delta: int, tolerance_s: float
) -> tuple[np.ndarray, np.ndarray]:
    """Pairs of poses (times increasing) whose frames of the sequence (the frame within `tolerance_s` of each) are
    exactly `delta` frames apart."""
    order = np.argsort(frame_times, kind="stable")
    ids, best = matching_time_indices(times, frame_times[order], tolerance_s)
    frame = best  # the frame's rank in time, for each pose of `ids` (increasing with the pose's time)
    at = np.searchsorted(frame, frame + delta)
    ok = at < len(frame)
    ok[ok] = frame[at[ok]] == frame[ok] + delta
    return ids[ok], ids[at[ok]]


def _pairs_by_axis(
    axis: np.ndarray, delta: float, snap: float | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The point exactly `delta` further along a non-decreasing `axis` (time, or distance travelled) from each pose:
    (i, a, b, w), the pose i and its partner at axis[a] + w (axis[b] - axis[a]). Where a pose lies within `snap` of
    the point (None: to rounding, RPE_M_ROUNDING x the distance), that pose (a = b, w = 0); otherwise the poses a
    before and b after it, where both lie within RPE_BRACKET x delta of it."""
    n = len(axis)
    i = np.arange(n)
    target = axis + delta
    if snap is None:
        snap = RPE_M_ROUNDING * np.maximum(delta, np.abs(target))
    a = np.searchsorted(axis, target, side="left") - 1  # the last pose before the point
    b = np.searchsorted(axis, target, side="right")  # the first pose beyond it
    a_c, b_c = np.maximum(a, 0), np.minimum(b, n - 1)
    at = np.minimum(a + 1, n - 1)  # the first pose at or beyond it
    near = np.where(np.abs(axis[a_c] - target) <= np.abs(axis[at] - target), a_c, at)
    on = (np.abs(axis[near] - target) <= snap) & (near > i)
    reach = RPE_BRACKET * delta
    around = ~on & (a >= 0) & (b < n) & (axis[a_c] >= target - reach) & (axis[b_c] <= target + reach) & (a_c > i)
    keep = on | around
    a_k = np.where(on, near, a_c)[keep]
    b_k = np.where(on, near, b_c)[keep]
    span = axis[b_k] - axis[a_k]
    w = np.where(on[keep], 0.0, (target[keep] - axis[a_k]) / np.where(span > 0, span, 1.0))
    return i[keep], a_k, b_k, w


def _interpolated(poses: np.ndarray, a: np.ndarray, b: np.ndarray, w: np.ndarray) -> np.ndarray:
    """The 4x4 poses at weight `w` between poses[a] and poses[b]: positions linearly, rotations by slerp
    (R_a exp(w log(R_a^T R_b))), batched; poses[a] itself where w is 0."""
    out = poses[a].copy()
    move = w > 0
    if not move.any():
        return out
    ra, rb, wm = poses[a[move], :3, :3], poses[b[move], :3, :3], w[move]
    out[move, :3, :3] = ra @ _rotation_part(np.swapaxes(ra, 1, 2) @ rb, wm)
    out[move, :3, 3] = (1.0 - wm)[:, None] * poses[a[move], :3, 3] + wm[:, None] * poses[b[move], :3, 3]
    return out


def _rotation_part(rel: np.ndarray, w: np.ndarray) -> np.ndarray:
    """exp(w log(R)) of rotation matrices (N, 3, 3): the same axis, w times the angle (in [0, pi])."""
    q = rotmat_to_quat(rel)  # qw >= 0: the half angle in [0, pi/2]
    sin_half = np.linalg.norm(q[:, :3], axis=1)
    half = w * np.arctan2(sin_half, q[:, 3])
    axis = q[:, :3] / np.where(sin_half > 0, sin_half, 1.0)[:, None]
    return quat_to_rotmat(np.column_stack([axis * np.sin(half)[:, None], np.cos(half)]))


def _inverse(poses: np.ndarray) -> np.ndarray:
    """The inverses of rigid 4x4 poses (rotation transposed, translation -R^T t): exact and 10x numpy's inv."""
    out = np.empty_like(poses)
    rt = np.swapaxes(poses[:, :3, :3], 1, 2)
    out[:, :3, :3] = rt
    out[:, :3, 3] = -np.einsum("nij,nj->ni", rt, poses[:, :3, 3])
    out[:, 3] = (0.0, 0.0, 0.0, 1.0)
    return out


def _path_along(gt: Trajectory, times: np.ndarray) -> np.ndarray:
    """The distance travelled along the ground truth's path (its rows in time order) up to each of `times`."""
    if len(gt) < 2:
        return np.zeros(len(times))
    travelled = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(gt.positions, axis=0), axis=1))])
    return np.interp(times, gt.timestamps, travelled)


def _pairs_by_index(n: int, delta: int) -> tuple[np.ndarray, np.ndarray]:
    ids = np.arange(0, n, delta)
    return ids[:-1], ids[1:]


def _pairs_by_path(positions: np.ndarray, delta_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Consecutive pairs: a new pose each time the path travelled since the previous one reaches delta_m."""
    steps = np.linalg.norm(np.diff(positions, axis=0), axis=1)
    ids, travelled = [0], 0.0
    for k, step in enumerate(steps, start=1):
        travelled += float(step)
        if travelled >= delta_m:
            ids.append(k)
            travelled = 0.0
    ids_a = np.array(ids)
    return ids_a[:-1], ids_a[1:]


def _angles_deg(rot: np.ndarray) -> np.ndarray:
    """The rotation angles of rotation matrices (N, 3, 3) in degrees, accurate near 0 (from the axis-angle vector's
    norm)."""
    cos = (np.trace(rot, axis1=1, axis2=2) - 1.0) / 2.0
    skew = np.stack([rot[:, 2, 1] - rot[:, 1, 2], rot[:, 0, 2] - rot[:, 2, 0], rot[:, 1, 0] - rot[:, 0, 1]], axis=1)
    return np.degrees(np.arctan2(np.linalg.norm(skew, axis=1) / 2.0, cos))


# ----------------------------------------------------------------------------------------------- KITTI


@dataclass(frozen=True)
class KittiResult:
    """KITTI's odometry metric: the mean over every segment of 100..800 m starting every 10 frames of the
    translation error per metre (reported in %) and the rotation error per metre (deg/m)."""

    t_pct: float
    r_deg_per_m: float
    n_segments: int
    per_length: dict[int, tuple[float, float, int]]  # length -> (t %, r deg/m, segments)
    alignment: str

    def to_dict(self) -> dict:
        return {
            "metric": "kitti",
            "alignment": self.alignment,
            "kitti_t_pct": self.t_pct,
            "kitti_r_deg_m": self.r_deg_per_m,
            "kitti_segments": self.n_segments,
        }


def kitti(
    gt: Trajectory,
    est: Trajectory,
    alignment: Alignment | str = "sim3",
    lengths: tuple[int, ...] = KITTI_LENGTHS_M,
    step: int = KITTI_STEP_FRAMES,
    tolerance_s: float = DEFAULT_TOLERANCE_S,
) -> KittiResult:
    """KITTI's segment errors (evaluate_odometry.cpp's calcSequenceErrors) after the alignment; segments are
    measured along the ground truth's path, over the associated poses (one per frame for KITTI files)."""
    alignment = Alignment.parse(alignment) if isinstance(alignment, str) else alignment
    pairs = associate(gt, est, tolerance_s)
    q = matrices(pairs.gt)
    p = aligned(pairs.est, alignment.fit(pairs.est.positions, pairs.gt.positions))
    dist = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(q[:, :3, 3], axis=0), axis=1))])
    firsts, lasts, lens = [], [], []
    for first in range(0, len(q), step):
        for length in lengths:
            last = int(np.searchsorted(dist, dist[first] + length, side="right"))  # first frame beyond
            if last < len(q):
                firsts.append(first)
                lasts.append(last)
                lens.append(length)
    if not firsts:
        raise NoPairs(f"the ground truth's path ({dist[-1]:.1f} m) is shorter than {min(lengths)} m: no segment")
    f, la, ln = np.array(firsts), np.array(lasts), np.array(lens, float)
    delta_gt = _inverse(q[f]) @ q[la]
    delta_est = _inverse(p[f]) @ p[la]
    err = _inverse(delta_est) @ delta_gt
    cos = np.clip(0.5 * (np.trace(err[:, :3, :3], axis1=1, axis2=2) - 1.0), -1.0, 1.0)
    r_err = np.arccos(cos) / ln
    t_err = np.linalg.norm(err[:, :3, 3], axis=1) / ln
    per_length = {
        int(length): (float(100 * t_err[ln == length].mean()), float(np.degrees(r_err[ln == length].mean())), int(n))
        for length, n in zip(*np.unique(ln, return_counts=True), strict=True)
    }
    return KittiResult(float(100 * t_err.mean()), float(np.degrees(r_err.mean())), len(f), per_length, str(alignment))


# -------------------------------------------------------------------------------------------- helpers


def _finite(gt: Trajectory) -> Trajectory:
    """The ground truth's rows with a finite pose (TUM-Mono's groundtruthSync has NaN rows in the middle)."""
    ok = np.isfinite(gt.positions).all(axis=1) & np.isfinite(gt.quaternions).all(axis=1)
    return gt if ok.all() else _take(gt, np.flatnonzero(ok))


def _flat(prefix: str, s: ErrorStats) -> dict:
    return {f"{prefix}_{k}": v for k, v in asdict(s).items()}
