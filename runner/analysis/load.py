"""Load a campaign's results for analysis: the table, its evaluated runs, the metrics it has."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from runner.errors import SlamRunError
from runner.results.vocabulary import STUDY_METRICS, TRAJECTORY_STATS_METRICS


def load_results(path: Path) -> pd.DataFrame:
    """results.csv or results.parquet, or a results directory: its ledger when it has one (the truth, also while
    a campaign runs and before its first export), else the table it holds."""
    path = Path(path)
    if path.is_dir() and (path / "ledger.sqlite").is_file():
        from runner.engine.export import results_frame
        from runner.engine.ledger import Ledger

        ledger = Ledger(path / "ledger.sqlite", read_only=True)
        try:
            df = results_frame(ledger)
        finally:
            ledger.close()
        if df.empty:
            raise SlamRunError(f"{path}: no run in its ledger yet")
        return df
    if path.is_dir():
        path = path / "results.parquet" if (path / "results.parquet").exists() else path / "results.csv"
    if not path.exists():
        raise SlamRunError(f"{path}: no results; run `slamrun campaign` first")
    df = pd.read_parquet(path) if path.suffix == ".parquet" else pd.read_csv(path)
    if "method" not in df.columns:
        raise SlamRunError(f"{path}: no 'method' column; expected a slamrun results table")
    return df


def evaluated(df: pd.DataFrame, metrics: list[str]) -> pd.DataFrame:
    """Runs that ended `done` with every metric finite (the study's 'blank runs' are the others; a run that
    timed out or got lost is a failure even when it wrote poses that could be evaluated)."""
    present = [m for m in metrics if m in df.columns]
    if "status" in df.columns:
        df = df[df["status"] == "done"]
    return df.dropna(subset=present)


def metrics_for(df: pd.DataFrame) -> list[str]:
    """The metrics this table has values of: the study's six (e_s' if present, else e_s), then the ATE, RPE and
    KITTI figures of datasets that ask for them."""

    def has(m: str) -> bool:
        return m in df.columns and bool(df[m].notna().any())

    out = []
    for m in STUDY_METRICS:
        if has(m):
            out.append(m)
        elif m == "e_s_sym" and has("e_s"):
            out.append("e_s")
    return out + [m for m in TRAJECTORY_STATS_METRICS if has(m)]
