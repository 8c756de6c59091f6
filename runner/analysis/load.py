"""Load a campaign's results for analysis: evaluated runs kept, failed runs counted per kind."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from runner.errors import SlamRunError
from runner.ledger import METHOD_FAILURES

ACCURACY = ["e_t", "e_r", "e_s_sym", "e_start", "e_end", "e_rmse"]  # the study's six metrics (e_s' for scale)
LABELS = {
    "e_t": "translation drift e_t",
    "e_r": "rotation drift e_r (deg)",
    "e_s": "scale drift e_s",
    "e_s_sym": "scale drift e_s'",
    "e_align": "alignment error e_align",
    "e_start": "start-segment RMSE",
    "e_end": "end-segment RMSE",
    "e_rmse": "RMSE (both segments)",
}


def load_results(path: Path) -> pd.DataFrame:
    """results.csv or results.parquet, or a results directory holding them."""
    path = Path(path)
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


def failure_table(df: pd.DataFrame) -> pd.DataFrame:
    """Per method: runs, evaluated, and each failure kind, counts and percentages."""
    rows = []
    for method, g in df.groupby("method", sort=True):
        n = len(g)
        row = {"method": method, "runs": n}
        if "eval_status" in g.columns:
            row["evaluated"] = int((g["eval_status"] == "ok").sum())
            row["not evaluable"] = int(((g.get("status") == "done") & (g["eval_status"] != "ok")).sum())
        if "failure" in g.columns:
            for kind in (*METHOD_FAILURES, "infra"):
                row[kind] = int((g["failure"] == kind).sum())
        rows.append(row)
    out = pd.DataFrame(rows)
    if "failure" in df.columns and len(out):
        out["failure_pct"] = 100 * out[list(METHOD_FAILURES)].sum(axis=1) / out["runs"]
    return out


def metrics_for(df: pd.DataFrame) -> list[str]:
    """The study's metrics that this table has (e_s' if present, else e_s)."""
    out = []
    for m in ACCURACY:
        if m in df.columns:
            out.append(m)
        elif m == "e_s_sym" and "e_s" in df.columns:
            out.append("e_s")
    return out
