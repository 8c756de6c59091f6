"""The paths of a sequence's runs over its ground truth, aligned as their metric aligns them: each method's best,
median and worst evaluated run, for the report's static trajectory figures and its interactive views."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from slamrun.core.metrics import Alignment
from slamrun.engine.paths import RunPaths
from slamrun.errors import MetricError, SlamRunError
from slamrun.results.catalogue import E_ALIGN


@dataclass(frozen=True)
class RunPath:
    method: str
    which: str  # best, median or worst (by the metric)
    value: float  # the run's value of the metric
    trial: str
    direction: str
    positions: np.ndarray  # (n, 3), aligned to the ground truth


@dataclass(frozen=True)
class SequencePaths:
    sequence: str
    metric: str  # ate_rmse (a Sim(3) over every pose) or e_align (the start segment's Sim(3))
    units: str  # the ground truth's: m, or "ground-truth units" (TUM-Mono: arbitrary scale)
    layout: str  # the sequence's dataset layout (kitti: camera frame, y down)
    gt: np.ndarray  # (n, 3); NaN rows where the ground truth has no pose (TUM-Mono between its segments)
    full: np.ndarray | None  # the whole path where the sequence has one (groundtruth_full.txt)
    runs: list[RunPath]
    alignment: str = "sim3"  # ATE's, as the campaign evaluated the runs (sim3, se3, none, first:N, se3:first:N)

    def plane(self) -> tuple[int, int]:
        """The two coordinates in which the ground truth spreads most, in axis order: the top view's axes."""
        pts = self.gt[np.isfinite(self.gt).all(axis=1)]
        if self.full is not None:
            pts = np.vstack([pts, self.full])
        spread = np.ptp(pts, axis=0) if len(pts) else np.ones(3)
        a, b = sorted(np.argsort(-spread)[:2])
        return int(a), int(b)

    def up(self) -> tuple[int, int]:
        """The vertical coordinate (the one the top view leaves out) and its sign: KITTI's camera frame has y down."""
        third = ({0, 1, 2} - set(self.plane())).pop()
        return third, -1 if self.layout == "kitti" else 1

    def ends(self) -> tuple[np.ndarray, np.ndarray]:
        """The ground truth's first and last pose with a position."""
        pts = self.gt[np.isfinite(self.gt).all(axis=1)]
        return pts[0], pts[-1]

    def gt_label(self) -> str:
        finite = np.isfinite(self.gt).all(axis=1)
        return "ground truth" if finite.all() else "ground truth (start and end segments)"

    def aligned_by(self) -> str:
        if self.metric == E_ALIGN:
            return "aligned by the start segment's Sim(3)"
        a = Alignment.parse(self.alignment)
        if a.kind == "none":
            return "not aligned (ATE without alignment)"
        over = f"the first {a.first_n} poses" if a.first_n else "all poses"
        return f"aligned by {'a Sim(3)' if a.kind == 'sim3' else 'an SE(3)'} over {over} (ATE)"


def sequence_paths(df: pd.DataFrame, sequence: str, metric: str) -> SequencePaths | None:
    """The best, median and worst evaluated run by `metric` of each method on `sequence`, read from their run
    folders and aligned to the ground truth; None where none could be read (run folders moved, no ground truth)."""
    from slamrun.core.trajectory import read_tum

    ok = df[(df.sequence.astype(str) == sequence)].dropna(subset=[metric])
    if "status" in ok.columns:
        ok = ok[ok.status == "done"]
    gt, full, layout, runs, alignment = None, None, None, [], "sim3"
    for method, g in ok.groupby("method", sort=True):
        g = g.sort_values(metric)
        picks = {"best": g.iloc[0], "median": g.iloc[(len(g) - 1) // 2], "worst": g.iloc[-1]}
        drawn = set()
        for which, row in picks.items():
            if not isinstance(row.run_dir, str) or not row.run_dir or row.run_dir in drawn:
                continue  # no run folder (a table from elsewhere), or a run already drawn (one or two runs)
            drawn.add(row.run_dir)
            run_dir = Path(row.run_dir)
            try:
                if gt is None:
                    gt, full, layout = sequence_truth(
                        Path(json.loads(RunPaths.run_json(run_dir).read_text())["sequence_dir"])
                    )
                traj = read_tum(RunPaths.trajectory(run_dir))
            except (OSError, KeyError, ValueError, TypeError, SlamRunError):
                continue
            alignment = run_alignment(row.get("eval_settings"))
            try:
                positions = aligned(traj, gt, metric, alignment)
            except MetricError:
                continue  # its figure was made, so it aligns: a file changed since
            trial = str(row.trial) if "trial" in row.index else ""
            direction = str(row.direction) if "direction" in row.index else ""
            runs.append(RunPath(str(method), which, float(row[metric]), trial, direction, positions))
    if gt is None or not runs:
        return None
    return SequencePaths(sequence, metric, units_of(layout), layout, gt.positions, full, runs, alignment)


def sequence_truth(sequence_dir: Path):
    """A sequence's ground truth (a Trajectory), its whole path where it has one (groundtruth_full.txt) and its
    layout: what a view draws its runs over."""
    from slamrun.core.trajectory import read_tum
    from slamrun.datasets.layouts import open_sequence

    seq = open_sequence(sequence_dir)
    full_path = sequence_dir / "groundtruth_full.txt"
    return seq.groundtruth(), read_tum(full_path).positions if full_path.is_file() else None, seq.layout


def units_of(layout: str) -> str:
    """The ground truth's units: TUM-Mono's has an arbitrary scale."""
    return "ground-truth units" if layout == "tum-mono" else "m"


def aligned(traj, gt, metric: str, alignment: str = "sim3") -> np.ndarray:
    """A run's positions in the ground truth's frame, as its metric aligned them: TUM-Mono's e_align by the start
    segment's Sim(3); ATE by the transform its ATE found (the campaign's `alignment`: sim3, se3, none, first:N, over
    the poses it paired), so the drawn distance is the figure the tables give. MetricError says why it cannot be
    (nothing paired, a first:N longer than the run, under three poses in the start segment)."""
    from slamrun.core import metrics
    from slamrun.core.alignment import align_sim3
    from slamrun.core.evaluation import ASSOCIATION_TOLERANCE_S, ground_truth_rows

    if metric != E_ALIGN:
        return metrics.ate(gt, traj, alignment, ASSOCIATION_TOLERANCE_S).transform.apply(traj.positions)
    valid = np.isfinite(gt.positions).all(axis=1)
    match = ground_truth_rows(gt.timestamps, traj.timestamps)
    use = (match >= 0) & valid[np.maximum(match, 0)] & (match < len(gt) // 2)
    if use.sum() < 3:
        raise MetricError(f"{int(use.sum())} of its poses meet the start segment's ground truth (3 needed)")
    return align_sim3(traj.positions[use], gt.positions[match[use]]).apply(traj.positions)


def run_alignment(eval_settings) -> str:
    """The alignment a run's figures were made with (its recorded evaluation settings), sim3 where none is recorded."""
    try:
        found = json.loads(eval_settings).get("alignment") if isinstance(eval_settings, str) else None
    except (ValueError, AttributeError):
        found = None
    return found if isinstance(found, str) and found else "sim3"
