"""Export the ledger to results.csv and results.parquet, and summarise it per method."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pandas as pd

from runner.ledger import METHOD_FAILURES, METRIC_COLUMNS, RESOURCE_COLUMNS, Ledger

COLUMNS = (
    "method",
    "sequence",
    "direction",
    "trial",
    "status",
    "failure",
    "eval_status",
    *METRIC_COLUMNS,
    *RESOURCE_COLUMNS,
    "method_name",
    "dataset",
    "settings",
    "attempts",
    "exit_code",
    "message",
    "run_dir",
    "key",
)


def results_frame(ledger: Ledger) -> pd.DataFrame:
    rows = ledger.rows(active_only=True)
    df = pd.DataFrame(rows, columns=list(rows[0]) if rows else None)
    if df.empty:
        return pd.DataFrame(columns=list(COLUMNS))
    df = df.rename(columns={"method": "method_name", "state": "status"}).rename(columns={"label": "method"})
    for col in METRIC_COLUMNS + RESOURCE_COLUMNS:
        df[col] = pd.to_numeric(df[col], errors="coerce")
    return df[list(COLUMNS)]


def export(ledger: Ledger, results: Path) -> Path:
    """Write results.csv and results.parquet atomically; returns the CSV path."""
    df = results_frame(ledger)
    csv_path = results / "results.csv"
    tmp = csv_path.with_suffix(".csv.tmp")
    df.to_csv(tmp, index=False)
    os.replace(tmp, csv_path)
    pq = results / "results.parquet"
    tmp = pq.with_suffix(".parquet.tmp")
    df.to_parquet(tmp, index=False)
    os.replace(tmp, pq)
    return csv_path


def method_summary(df: pd.DataFrame) -> pd.DataFrame:
    """Per method: runs, state counts, failures by kind, success rate, medians of the main metrics.

    Infrastructure failures (`infra`) are not the method's result: they have their own column and are
    left out of `failed` and of the success rate (done / (done + method failures)).
    """
    out = []
    for method, g in df.groupby("method", sort=False):
        infra = (g.status == "failed") & (g.failure == "infra")
        method_failed = (g.status == "failed") & ~infra
        done = int((g.status == "done").sum())
        results = done + int(method_failed.sum())
        ok = g[g.eval_status == "ok"]
        row = {
            "method": method,
            "runs": len(g),
            "done": done,
            "failed": int(method_failed.sum()),
            "infra": int(infra.sum()),
            "pending": int(g.status.isin(["pending", "running"]).sum()),
            "success_pct": 100.0 * done / results if results else np.nan,
            "evaluated": len(ok),
        }
        for kind in METHOD_FAILURES:
            row[kind] = int((method_failed & (g.failure == kind)).sum())
        for m in ("e_t", "e_r", "e_s_sym", "e_align", "e_rmse"):
            row[f"median_{m}"] = ok[m].median() if len(ok) else np.nan
        row["median_fps"] = g.fps.median() if g.fps.notna().any() else np.nan
        out.append(row)
    return pd.DataFrame(out)
