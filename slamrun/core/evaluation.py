"""The TUM-Mono benchmark's metrics (Engel et al. 2016). Pure functions, no I/O.

See docs: association within 1 ms, start/end segments split by ground-truth rows, a Sim(3) alignment
per segment, and the drift figures e_t, e_r, e_s, e_align, e_start, e_end, e_rmse derived from them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from slamrun.core.alignment import Sim3, align_sim3, rmse, rotation_angle_deg
from slamrun.core.nearest import nearest
from slamrun.core.trajectory import Trajectory
from slamrun.results.catalogue import TUM_MONO_METRICS
from slamrun.results.vocabulary import EvalStatus

ASSOCIATION_TOLERANCE_S = 1e-3
MIN_SEGMENT_POSES = 3  # a Sim(3) alignment needs at least three poses to be determined


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
        ok = self.status is EvalStatus.ok
        d = {"status": self.status.value}
        for k in TUM_MONO_METRICS:
            d[k] = getattr(self, k) if ok else None
        d.update(n_poses=self.n_poses, detail=self.detail, e_s_sym=self.e_s_sym if ok else None)
        return d


def _failed(status: EvalStatus, n: int, detail: str) -> TumMonoResult:
    return TumMonoResult(status=status, n_poses=n, detail=detail)


def tum_mono_file(gt: Trajectory, est: Trajectory) -> TumMonoResult:
    """`tum_mono` as the benchmark judges a FILE: one that held a NaN or infinite row is a failed run
    (status nan), whatever its finite rows give. (The campaign instead drops such rows, counts them in the
    run's read report and evaluates the rest.)"""
    dropped = est.report.n_nonfinite_dropped
    if dropped:
        return _failed(EvalStatus.nan, est.report.n_rows, f"the file holds {dropped} NaN or infinite row(s)")
    return tum_mono(gt, est)


def _rows_as_the_benchmark_reads(est: Trajectory) -> Trajectory:
    """The poses the benchmark's evaluator takes from a file: its rows sorted by time (MATLAB's `sort`, stable), a
    repeated time's every row kept in the file's order; the trajectory itself where the file repeats no time."""
    if est.as_read is None or not est.report.n_duplicates_dropped:
        return est
    rows = est.as_read
    order = np.argsort(rows.timestamps, kind="stable")
    return Trajectory(rows.timestamps[order], rows.positions[order], rows.quaternions[order], report=est.report)


def ground_truth_rows(gt_times: np.ndarray, est_times: np.ndarray, tol: float = ASSOCIATION_TOLERANCE_S) -> np.ndarray:
    """For each estimated timestamp the index of the nearest ground-truth row within `tol`, else -1.

    `gt_times` must be sorted increasingly.
    """
    row, distance = nearest(gt_times, est_times)
    return np.where(distance <= tol, row, -1)


def tum_mono(gt: Trajectory, est: Trajectory) -> TumMonoResult:
    """Evaluate one estimated trajectory against a TUM-Mono groundtruthSync (NaN rows allowed).

    The start, end and union alignments come from one pass over each segment and one batched SVD
    (see `_align_segments`); docs/tum-mono.md has the definitions. A file that repeats a timestamp is evaluated
    with every row of it, as the benchmark's evaluator reads the file.
    """
    est = _rows_as_the_benchmark_reads(est)
    n = len(est)
    if n == 0:
        return _failed(EvalStatus.empty, 0, "no pose in the estimate")
    p = est.positions
    if not (np.isfinite(p).all() and np.isfinite(est.quaternions).all()):
        return _failed(EvalStatus.nan, n, "the estimate holds NaN or infinite values")
    gt_t = gt.timestamps
    t = est.timestamps
    match, distance = nearest(gt_t, t)
    far = distance > ASSOCIATION_TOLERANCE_S
    if far.any():
        bad = t[np.flatnonzero(far)[0]]
        return _failed(
            EvalStatus.unassociated, n, f"{np.count_nonzero(far)} poses (first t={bad:.6f}) have no GT within 1 ms"
        )
    n_gt = len(gt_t)
    # Segments by ground-truth rows (1-based: 1..floor(n/2) and ceil(n/2)..n); est is sorted, so each
    # segment's time range is one slice of it, of which the rows with a finite ground truth take part.
    lo = np.searchsorted(t, (gt_t[0], gt_t[(n_gt + 1) // 2 - 1]), side="left")
    hi = np.searchsorted(t, (gt_t[n_gt // 2 - 1], gt_t[-1]), side="right")
    valid = gt.finite_rows
    seg_est, seg_gt = [], []
    for k in (0, 1):
        m = match[lo[k] : hi[k]]
        keep = valid[m]
        if keep.all():
            seg_est.append(p[lo[k] : hi[k]])
            seg_gt.append(gt.positions[m])
        else:
            seg_est.append(p[lo[k] : hi[k]][keep])
            seg_gt.append(gt.positions[m[keep]])
    n_s, n_e = len(seg_est[0]), len(seg_est[1])
    if n_s < MIN_SEGMENT_POSES or n_e < MIN_SEGMENT_POSES:
        return _failed(EvalStatus.incomplete, n, f"segment poses: start {n_s}, end {n_e}; need >= {MIN_SEGMENT_POSES}")

    (s_start, s_end), (e_start, e_end, e_rmse) = _align_segments(seg_est, seg_gt)
    if lo[1] < hi[0] and valid[match[lo[1] : hi[0]]].any():  # shared poses: a finite middle GT row, even count
        union = slice(lo[0], hi[1])
        in_union = valid[match[union]] & ((t[union] <= gt_t[n_gt // 2 - 1]) | (t[union] >= gt_t[(n_gt + 1) // 2 - 1]))
        both_est, both_gt = p[union][in_union], gt.positions[match[union][in_union]]
        e_rmse = rmse(align_sim3(both_est, both_gt).apply(both_est), both_gt)

    with np.errstate(all="ignore"):  # a degenerate segment (scale 0 or NaN) ends as status nan below
        # e_align: RMSE between the trajectory aligned by the start and by the end segment, over all poses.
        a_mat = s_end.scale * s_end.rotation - s_start.scale * s_start.rotation
        diff = p @ a_mat.T + (s_end.translation - s_start.translation)
        e_align = math.sqrt(float(np.einsum("ij,ij->", diff, diff)) / n)
        # Drift S_end S_start^-1: rotation R_e R_s^T, scale s_e/s_s, translation t_e - (s_e/s_s) R_e R_s^T t_s.
        rel_rot = s_end.rotation @ s_start.rotation.T
        e_s = float(np.float64(s_start.scale) / s_end.scale)
        drift_t = s_end.translation - (rel_rot @ s_start.translation) / e_s
        e_t = math.sqrt(float(drift_t @ drift_t))
        e_r = rotation_angle_deg(rel_rot)
    values = (e_t, e_r, e_s, e_align, e_start, e_end, e_rmse)
    if not all(math.isfinite(v) for v in values):
        return _failed(EvalStatus.nan, n, "degenerate alignment (all poses of a segment at one point)")
    return TumMonoResult(EvalStatus.ok, *values, n_poses=n)


def _umeyama(cov: np.ndarray, var_source: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotations and scales of stacked Sim(3) problems from their cross-covariances (k, 3, 3) =
    sum of centred target x centred source^T, and the source's centred sums of squares (k,).

    The same solution as `align_sim3`: R = U D V^T with the reflection fixed, s = trace(D S) / var.
    """
    u, sv, vt = np.linalg.svd(cov)
    rots = u @ vt
    flip = np.linalg.det(rots) < 0
    if flip.any():  # D = diag(1, 1, -1) where U V^T is a reflection
        d = np.ones(sv.shape)
        d[flip, 2] = -1.0
        rots = (u * d[:, None, :]) @ vt
        sv = sv * d
    with np.errstate(invalid="ignore", divide="ignore"):
        return rots, sv.sum(axis=1) / var_source


def _align_segments(est: list[np.ndarray], gt: list[np.ndarray]) -> tuple[list[Sim3], list[float]]:
    """Sim(3) alignments of the start and the end segment, and the RMSEs after alignment of the start
    segment, the end segment and the two together (each as `align_sim3` would give), with one batched SVD."""
    sets = [(est[0], gt[0]), (est[1], gt[1]), (np.concatenate(est), np.concatenate(gt))]
    mu_e, mu_g, centred, cov, var = [], [], [], np.empty((3, 3, 3)), np.empty(3)
    for k, (e, g) in enumerate(sets):
        mu_e.append(e.sum(axis=0) / len(e))
        mu_g.append(g.sum(axis=0) / len(g))
        ec, gc = e - mu_e[k], g - mu_g[k]
        centred.append((ec, gc))
        cov[k] = gc.T @ ec
        var[k] = np.einsum("ij,ij->", ec, ec)
    rots, scales = _umeyama(cov, var)
    maps = scales[:, None, None] * rots
    errors = []
    for k, (ec, gc) in enumerate(centred):
        r = ec @ maps[k].T - gc
        errors.append(math.sqrt(float(np.einsum("ij,ij->", r, r)) / len(r)))
    sims = [Sim3(rots[k], mu_g[k] - maps[k] @ mu_e[k], float(scales[k])) for k in (0, 1)]
    return sims, errors


def tum_mono_many(gt: Trajectory, ests: list[Trajectory]) -> list[TumMonoResult]:
    """`tum_mono_file` for many estimates against one ground truth: the same figures, to rounding.

    The usual estimate (every pose within 1 ms of a ground-truth row, both segments of at least three poses,
    none in both) is evaluated together with the others: association, segment sums (`np.add.reduceat`) and
    the Sim(3) fits (one batched SVD) take a few numpy calls for all of them instead of some sixty a file.
    Any other estimate, or one whose alignment degenerates, takes `tum_mono_file`, for its status and detail.
    """
    ests = [_rows_as_the_benchmark_reads(e) for e in ests]
    out: list[TumMonoResult | None] = [None] * len(ests)
    batch = [k for k, e in enumerate(ests) if len(e) and not e.report.n_nonfinite_dropped]
    if batch and len(gt) >= 2:
        for k, res in zip(batch, _tum_mono_usual(gt, [ests[k] for k in batch]), strict=True):
            out[k] = res
    return [res if res is not None else tum_mono_file(gt, e) for res, e in zip(out, ests, strict=True)]


def _first_rows(counts: np.ndarray) -> np.ndarray:
    """Where each of consecutive groups of `counts` rows starts."""
    first = np.zeros(len(counts), int)
    np.cumsum(counts[:-1], out=first[1:])
    return first


class _Moments(NamedTuple):
    """Groups of point pairs: means (k, 3), centred rows (3, rows), cross-covariances (k, 3, 3) = sum of centred
    target x centred source^T, and the source's centred sums of squares (k,)."""

    mu_e: np.ndarray
    mu_g: np.ndarray
    ec: np.ndarray
    gc: np.ndarray
    cov: np.ndarray
    var: np.ndarray


def _tum_mono_usual(gt: Trajectory, ests: list[Trajectory]) -> list[TumMonoResult | None]:
    """The batched part of `tum_mono_many`: each estimate's result, or None where it is not the usual case."""
    found = _usual_segments(gt, ests)
    if found is None:
        return [None] * len(ests)
    return _segment_fits(ests, *found)


def _usual_segments(gt: Trajectory, ests: list[Trajectory]) -> tuple | None:
    """The estimates of the usual case (every pose at a GT row, both segments long enough, finite) and their
    segments' rows: (files, rows per segment, estimate rows (3, n), GT rows (3, n)); None when there is none."""
    gt_t, n_gt = gt.timestamps, len(gt.timestamps)
    rows = np.fromiter((len(e) for e in ests), int, len(ests))
    starts = _first_rows(rows)
    t = np.concatenate([e.timestamps for e in ests])
    match, distance = nearest(gt_t, t)
    # each file's segments as tum_mono slices its sorted times: [lo, hi) by the GT rows' times
    lo_s = np.add.reduceat(t < gt_t[0], starts)
    hi_s = np.add.reduceat(t <= gt_t[n_gt // 2 - 1], starts)
    lo_e = np.add.reduceat(t < gt_t[(n_gt + 1) // 2 - 1], starts)
    hi_e = np.add.reduceat(t <= gt_t[-1], starts)
    candidate = (
        np.logical_and.reduceat(distance <= ASSOCIATION_TOLERANCE_S, starts)
        & (hi_s - lo_s >= MIN_SEGMENT_POSES)
        & (hi_e - lo_e >= MIN_SEGMENT_POSES)
    )
    for k in np.flatnonzero(candidate):  # (NaN or infinite positions make the figures NaN: `tum_mono` then)
        if not np.isfinite(ests[k].quaternions.sum()):
            candidate[k] = False
        elif lo_e[k] < hi_s[k] and gt.finite_rows[match[starts[k] + lo_e[k] : starts[k] + hi_s[k]]].any():
            candidate[k] = False  # a pose in both segments (an even GT row count with a finite middle row)
    files = np.flatnonzero(candidate)
    if len(files) == 0:
        return None
    # the segments' rows of every candidate, [start 1, end 1, start 2, end 2, ...], those with a finite GT row
    seg_len = np.column_stack((hi_s - lo_s, hi_e - lo_e))[files].ravel()
    seg_at = np.column_stack((starts + lo_s, starts + lo_e))[files].ravel()
    idx = np.repeat(seg_at - _first_rows(seg_len), seg_len) + np.arange(seg_len.sum())
    valid = gt.finite_rows[match[idx]]
    n_valid = np.add.reduceat(valid, _first_rows(seg_len)).reshape(-1, 2)
    enough = (n_valid >= MIN_SEGMENT_POSES).all(axis=1)
    files, n_seg = files[enough], n_valid[enough].ravel()
    if len(files) == 0:
        return None
    in_files = np.repeat(np.repeat(enough, 2), seg_len)
    keep = valid[in_files]
    parts = [ests[k].positions[a:b] for k in files for a, b in ((lo_s[k], hi_s[k]), (lo_e[k], hi_e[k]))]
    # coordinates first, (3, rows): every sum below runs along contiguous memory
    e_rows = np.ascontiguousarray(np.concatenate(parts)[keep].T)
    g_rows = np.ascontiguousarray(gt.positions[match[idx[in_files][keep]]].T)
    return files, n_seg, e_rows, g_rows


def _segment_fits(
    ests: list[Trajectory], files: np.ndarray, n_seg: np.ndarray, e_rows: np.ndarray, g_rows: np.ndarray
) -> list[TumMonoResult | None]:
    """Each usual estimate's Sim(3) fits of its segments and of both together, and TUM-Mono's figures from them."""
    n_both = n_seg[0::2] + n_seg[1::2]
    first_seg, first_both = _first_rows(n_seg), _first_rows(n_both)

    seg, both = _moments(e_rows, g_rows, n_seg, first_seg), _moments(e_rows, g_rows, n_both, first_both)
    n_files = len(files)
    rots, scales = _umeyama(np.concatenate((seg.cov, both.cov)), np.concatenate((seg.var, both.var)))
    with np.errstate(all="ignore"):  # a degenerate fit gives NaN or inf: that file takes `tum_mono`
        maps = scales[:, None, None] * rots
        maps_seg, maps_both = maps[: 2 * n_files], maps[2 * n_files :]
        errors = []
        for mom, m, n, first in ((seg, maps_seg, n_seg, first_seg), (both, maps_both, n_both, first_both)):
            per_row = np.repeat(m.reshape(-1, 9).T, n, axis=1).reshape(3, 3, -1)  # each row's map, (3, 3, rows)
            r = np.einsum("abj,bj->aj", per_row, mom.ec) - mom.gc
            errors.append(np.sqrt(np.add.reduceat(np.einsum("ij,ij->j", r, r), first) / n))
        trans = seg.mu_g - np.einsum("fij,fj->fi", maps_seg, seg.mu_e)  # translations, [start 1, end 1, ...]
        rot_s, rot_e = rots[0 : 2 * n_files : 2], rots[1 : 2 * n_files : 2]
        scale_s, scale_e = scales[0 : 2 * n_files : 2], scales[1 : 2 * n_files : 2]
        a_mat_t = np.ascontiguousarray(np.swapaxes(maps_seg[1::2] - maps_seg[0::2], 1, 2))  # e_align: end fit
        # minus start fit, over all poses (transposed: p @ A^T)
        shift = trans[1::2] - trans[0::2]
        rel_rot = rot_e @ np.swapaxes(rot_s, 1, 2)
        e_s = scale_s / scale_e
        drift_t = trans[1::2] - np.einsum("fij,fj->fi", rel_rot, trans[0::2]) / e_s[:, None]
        e_t = np.sqrt(np.einsum("ij,ij->i", drift_t, drift_t))
        out: list[TumMonoResult | None] = [None] * len(ests)
        for i, k in enumerate(files):
            p = ests[k].positions
            diff = np.dot(p, a_mat_t[i])
            diff += shift[i]
            diff = diff.ravel()
            values = (
                float(e_t[i]),
                rotation_angle_deg(rel_rot[i]),
                float(e_s[i]),
                math.sqrt(float(np.dot(diff, diff)) / len(p)),
                float(errors[0][2 * i]),
                float(errors[0][2 * i + 1]),
                float(errors[1][i]),
            )
            if all(math.isfinite(v) for v in values):
                out[k] = TumMonoResult(EvalStatus.ok, *values, n_poses=len(p))
    return out


def _moments(e_rows: np.ndarray, g_rows: np.ndarray, n: np.ndarray, first: np.ndarray) -> _Moments:
    """The moments of the groups of n rows from `first`."""
    mu_e = np.add.reduceat(e_rows, first, axis=1) / n
    mu_g = np.add.reduceat(g_rows, first, axis=1) / n
    ec, gc = e_rows - np.repeat(mu_e, n, axis=1), g_rows - np.repeat(mu_g, n, axis=1)
    cov = np.add.reduceat((gc[:, None, :] * ec[None, :, :]).reshape(9, -1), first, axis=1)
    var = np.add.reduceat(np.einsum("ij,ij->j", ec, ec), first)
    return _Moments(mu_e.T, mu_g.T, ec, gc, cov.T.reshape(-1, 3, 3), var)
