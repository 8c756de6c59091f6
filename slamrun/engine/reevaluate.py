"""Settings always apply: a finished run whose figures were made with other evaluation settings than its dataset's
now (metrics, alignment, RPE's interval, min_coverage, coverage_mark, max_ate_rel) or by another version of the
evaluation code (run_evaluation.EVALUATION_VERSION) is evaluated again from its stored trajectory, its failure
decided again (min_coverage, max_ate_rel), and recorded in the ledger. No method runs again. The campaign does it at
its start, `slamrun report` before it writes, the dry run counts them ("12 runs to re-evaluate")."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import slamrun.methods
from slamrun.core.trajectory import Trajectory, read_tum
from slamrun.datasets.perturb import NONE, Perturbation
from slamrun.datasets.view import Direction
from slamrun.engine.ledger import Ledger
from slamrun.engine.paths import RunPaths
from slamrun.engine.run_evaluation import EvalSettings, evaluate_trajectory, run_frames, settle
from slamrun.engine.spec import CampaignSpec
from slamrun.errors import MethodFailure, SlamRunError, TrajectoryFormatError
from slamrun.results.catalogue import METRIC_COLUMNS, N_POSES
from slamrun.results.files import CampaignFiles
from slamrun.results.vocabulary import DIVERGED, IMPORTED, INFRA_FAILURES, UNDER_MIN_COVERAGE

LOST_BY_LOG = "the method reported it was lost"  # execute._classify's message of a loss it may recover from
FIGURES = tuple(c for c in METRIC_COLUMNS if c != N_POSES)  # cleared before the new ones are written


@dataclass(frozen=True)
class Target:
    """What a finished run is evaluated against now: its dataset's settings, its sequence, the view it ran on, and
    the indices of that view's frames its method takes (None: all)."""

    evaluation: EvalSettings
    sequence_dir: Path
    perturbation: Perturbation
    direction: Direction
    given: Callable[[int], np.ndarray | None]


def target_of(row: dict, spec: CampaignSpec) -> Target | None:
    """The target of a ledger row under `spec` (None where its dataset or method label is not the spec's)."""
    ds = next((d for d in spec.datasets if d.name == row.get("dataset")), None)
    if ds is None:
        return None
    if row.get("method_name") == IMPORTED:
        given = _all
    else:
        m = next((m for m in spec.methods if m.run_label == row.get("method")), None)
        if m is None:
            return None
        given = slamrun.methods.get(m.name)(m.params).frames_given
    name = row.get("perturbation") or NONE
    level = float(row["level"]) if row.get("level") is not None else 0.0
    pert = Perturbation.named(name, level, spec.perturbation_seed)
    return Target(ds.evaluation, ds.path / str(row["sequence"]), pert, Direction(row["direction"]), given)


def _all(n: int) -> None:
    return None


def stale(rows: Iterable[dict], spec: CampaignSpec) -> list[tuple[dict, Target]]:
    """The finished runs (done, or failed by the method) whose figures were made with other settings than their
    dataset's now, with their target."""
    out = []
    for row in rows:
        if row.get("status") not in ("done", "failed") or row.get("failure") in INFRA_FAILURES:
            continue
        target = target_of(row, spec)
        if target is not None and row.get("eval_settings") != target.evaluation.text():
            out.append((row, target))
    return out


def reevaluate(ledger: Ledger, spec: CampaignSpec, groundtruths: dict | None = None, log=print) -> int:
    """Evaluate again every stale run of `ledger` (`stale`) from its trajectory, record it; returns how many. The
    ground truths and frame times are read once per sequence (`groundtruths`: those the campaign loaded)."""
    from slamrun.datasets.layouts import open_sequence

    todo = stale(ledger.rows(), spec)
    sequences: dict[str, tuple[np.ndarray, Trajectory | None]] = {}
    done = 0
    for row, target in todo:
        key = str(target.sequence_dir)
        if key not in sequences:
            try:
                seq = open_sequence(target.sequence_dir)
                gt = (groundtruths or {}).get(key) if groundtruths and key in groundtruths else seq.groundtruth()
            except SlamRunError as exc:
                log(f"warning: {target.sequence_dir}: cannot re-evaluate its runs ({exc})")
                sequences[key] = (np.zeros(0), None)
                continue
            sequences[key] = (seq.timestamps, gt if spec.evaluate else None)
        times, gt = sequences[key]
        if not len(times):
            continue
        values = reevaluated(row, target, times, gt)
        ledger.finish(row["key"], "failed" if values["failure"] else "done", values)
        done += 1
    if done:
        log(f"re-evaluated {done} finished run(s) from their trajectories: their dataset's evaluation settings changed")
    return done


def reevaluated(row: dict, target: Target, sequence_times: np.ndarray, gt: Trajectory | None) -> dict:
    """A finished run's new ledger values: its figures from its stored trajectory under the target's settings, and
    the failure they decide from the one its process left. A run without a trajectory keeps its failure."""
    values: dict = {"eval_settings": target.evaluation.text(), "ended_at": row.get("ended_at")}
    judged = judged_failure(row)
    values["method_failure"] = judged
    path = RunPaths.trajectory(Path(row["run_dir"])) if row.get("run_dir") else None
    try:
        traj = read_tum(path) if path is not None and path.is_file() else None
    except (OSError, TrajectoryFormatError):
        traj = None
    if traj is None or not len(traj):
        values.update(failure=row.get("failure"), message=row.get("message"))
        return values
    kept = len(run_frames(sequence_times, target.perturbation, target.direction).view)
    try:
        given = target.given(kept)
    except MethodFailure:
        given = None
    frames = run_frames(sequence_times, target.perturbation, target.direction, given)
    values.update(dict.fromkeys(FIGURES), eval_status=None)
    figures, detail = evaluate_trajectory(traj, gt, frames, target.evaluation)
    values.update(figures)
    message = None if judged is None else LOST_BY_LOG if judged == "lost?" else row.get("message")
    settle(values, judged, message, detail, target.evaluation)
    return values


def judged_failure(row: dict) -> str | None:
    """The failure a run's process left before its evaluation decided (the ledger's method_failure; for a run
    recorded before that column, told from its failure and message)."""
    if row.get("method_failure") is not None or row.get("eval_settings"):
        return row.get("method_failure")
    failure, message = row.get("failure"), row.get("message") or ""
    if failure == DIVERGED or (failure == "lost" and (UNDER_MIN_COVERAGE in message or message.startswith("too few"))):
        return None
    if message == LOST_BY_LOG:
        return "lost?"
    return failure


def reevaluate_folder(results: Path, log=print) -> int:
    """The stale runs of a results folder evaluated again under its spec as run (spec.resolved.yaml), and its
    results.csv written again (`slamrun report` does this first); nothing while a campaign holds the folder (it
    re-evaluated at its start, and runs it finishes now are evaluated with its settings)."""
    from slamrun.engine.export import export
    from slamrun.engine.ledger import ResultsLock
    from slamrun.engine.spec_file import load_spec
    from slamrun.errors import LedgerLockedError

    if not CampaignFiles(results).spec.is_file() or not CampaignFiles(results).ledger.is_file():
        return 0
    lock = ResultsLock(results)
    try:
        lock.acquire()
    except LedgerLockedError:
        return 0
    try:
        try:
            spec = load_spec(CampaignFiles(results).spec, check_files=False, check_gpu=False)
        except SlamRunError as exc:
            log(f"warning: {results}: its spec as run cannot be read, so no run was re-evaluated ({exc})")
            return 0
        ledger = Ledger(CampaignFiles(results).ledger)
        try:
            n = reevaluate(ledger, spec, log=log)
            if n:
                export(ledger, results)
            return n
        finally:
            ledger.close()
    finally:
        lock.release()
