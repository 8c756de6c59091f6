"""One finished run as the live page shows it: its path over the ground truth (the report's interactive view, for
this run alone) and the tail of its log. A run is named by its ledger key; its folder is found under the campaign's
own `runs/` and nowhere else."""

from __future__ import annotations

import json
import os
import stat
from pathlib import Path

from slamrun.engine.ledger import Ledger
from slamrun.engine.paths import RunPaths
from slamrun.errors import MetricError, SlamRunError
from slamrun.results.catalogue import MAIN_METRICS
from slamrun.serve.folders import LEDGER

LOG_TAIL_BYTES = 8192
MAX_RUN_JSON = 4 << 20


def run_row(results: Path, key: str) -> dict | None:
    """The ledger's row of the run `key`, or None when the ledger has none."""
    if not key or len(key) > 512:
        return None
    ledger = Ledger(results / LEDGER, read_only=True)
    try:
        return ledger.get(key)
    finally:
        ledger.close()


def run_folder(results: Path, key: str) -> Path | None:
    """The finished run's folder, `runs/<key>` resolved inside the campaign's `runs/` (links out refused)."""
    runs = (results / "runs").resolve()
    try:
        folder = (runs / key).resolve(strict=True)
    except (OSError, RuntimeError):
        return None
    return folder if folder.is_relative_to(runs) and folder != runs and folder.is_dir() else None


def log_tail(results: Path, key: str) -> str | None:
    """The last LOG_TAIL_BYTES of a run's log (decoded, a broken first character dropped); None when the run or
    its log is not there. A run still running has no folder yet: its log is written where it runs."""
    folder = run_folder(results, key) if run_row(results, key) else None
    if folder is None:
        return None
    log = RunPaths.log(folder)
    try:
        fd = os.open(log, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
    except OSError:
        return None
    with os.fdopen(fd, "rb") as f:
        if not stat.S_ISREG(os.fstat(f.fileno()).st_mode):
            return None
        size = os.fstat(f.fileno()).st_size
        f.seek(max(size - LOG_TAIL_BYTES, 0))
        data = f.read(LOG_TAIL_BYTES)
    text = data.decode("utf-8", errors="replace")
    return text[1:] if size > LOG_TAIL_BYTES and text.startswith("\ufffd") else text


def path_figure(results: Path, key: str) -> dict:
    """The plotly figure of a done run's path over its sequence's ground truth, aligned as its main metric aligns
    it (TUM-Mono: the start segment's Sim(3); else the transform its ATE found): the report's view, for this run
    alone. SlamRunError says why there is none."""
    from slamrun.analysis.interactive import view_figure
    from slamrun.analysis.paths import RunPath, SequencePaths, aligned, run_alignment, sequence_truth, units_of
    from slamrun.core.trajectory import read_tum

    row = run_row(results, key)
    if row is None:
        raise SlamRunError(f"no run {key!r} in this campaign's ledger")
    if row["status"] != "done":
        raise SlamRunError(f"run {key} is {row['status']}: only a done run has a path to draw")
    folder = run_folder(results, key)
    if folder is None:
        raise SlamRunError(f"run {key}: its folder is not under this campaign's runs/ (moved or deleted)")
    run_json = RunPaths.run_json(folder)
    if not run_json.is_file() or run_json.stat().st_size > MAX_RUN_JSON:
        raise SlamRunError(f"run {key}: no readable run.json")
    gt, full, layout = sequence_truth(Path(json.loads(run_json.read_text()).get("sequence_dir")))
    metric = next((m for m in MAIN_METRICS if row.get(m) is not None), MAIN_METRICS[-1])
    alignment = run_alignment(row.get("eval_settings"))
    try:
        positions = aligned(read_tum(RunPaths.trajectory(folder)), gt, metric, alignment)
    except MetricError as e:
        raise SlamRunError(f"run {key}: its path cannot be aligned to the ground truth ({alignment}): {e}") from e
    value = row.get(metric)
    value = float(value) if value is not None else float("nan")
    run = RunPath(row["method"], "best", value, str(row["trial"]), str(row["direction"]), positions)
    paths = SequencePaths(str(row["sequence"]), metric, units_of(layout), layout, gt.positions, full, [run], alignment)
    title = f"{row['method']} on {row['dataset']}/{row['sequence']}, {row['direction']} trial {row['trial']}"
    figure = view_figure(paths, title)
    figure["data"][-1]["name"] = f"{row['method']} ({metric} {value:.4g})"
    return figure
