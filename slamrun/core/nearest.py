"""The nearest-in-time search, written once: for each of some times, the row of a sorted time column nearest to it
(TUM-Mono's association, the ground truth at the frames, a view's original timestamps, coverage, foreign times)."""

from __future__ import annotations

import numpy as np


def nearest(sorted_times: np.ndarray, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each of `times`, the index of the nearest of `sorted_times` (sorted increasingly, at least one) and the
    distance to it; of two at the same distance, the earlier."""
    gt_times, est_times = sorted_times, np.asarray(times, float)
    n = len(gt_times)
    if n < 2 or not np.isfinite(est_times).all():
        idx = np.searchsorted(gt_times, est_times)
        hi = np.minimum(idx, n - 1)
        lo = np.maximum(idx - 1, 0)
    else:  # interp's search starts from the last answer: fast on sorted times. Its floor is the row at or
        # before t, or (rounded) the one after, so the nearest row is lo or lo + 1 either way.
        lo = np.interp(est_times, gt_times, np.arange(n, dtype=float)).astype(np.intp)
        np.minimum(lo, n - 2, out=lo)
        hi = lo + 1
    d_hi = np.abs(gt_times[hi] - est_times)
    d_lo = np.abs(gt_times[lo] - est_times)
    take_lo = d_lo <= d_hi
    return np.where(take_lo, lo, hi), np.where(take_lo, d_lo, d_hi)
