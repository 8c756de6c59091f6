"""Export the ledger to results.csv and results.parquet (one row per run)."""

from __future__ import annotations

import os
from pathlib import Path

import pandas as pd

from slamrun.datasets.perturb import NONE
from slamrun.engine.ledger import Ledger
from slamrun.results.catalogue import METRIC_COLUMNS, RESOURCE_COLUMNS, TEXT_METRIC_COLUMNS
from slamrun.results.files import CampaignFiles

COLUMNS = (
    "method",
    "sequence",
    "direction",
    "perturbation",
    "level",
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
    "contended_attempts",
    "contended_message",
    "exit_code",
    "message",
    "host",
    "packages",
    "slamrun_commit",
    "eval_settings",
    "run_dir",
    "key",
)


def results_frame(ledger: Ledger) -> pd.DataFrame:
    rows = ledger.rows(active_only=True)
    df = pd.DataFrame(rows, columns=list(rows[0]) if rows else None)
    if df.empty:
        return pd.DataFrame(columns=list(COLUMNS))
    for col in COLUMNS:  # a ledger read read-only from an earlier version lacks the newer columns
        if col not in df.columns:
            df[col] = None
    df["perturbation"] = df["perturbation"].fillna(NONE)  # runs recorded before the axis: the baseline
    for col in (c for c in METRIC_COLUMNS + RESOURCE_COLUMNS if c not in TEXT_METRIC_COLUMNS):
        df[col] = pd.to_numeric(df[col], errors="coerce")
    return df[list(COLUMNS)]


def export(ledger: Ledger, results: Path) -> Path:
    """Write results.csv and results.parquet atomically; returns the CSV path."""
    df = results_frame(ledger)
    csv_path = CampaignFiles(results).results_csv
    tmp = csv_path.with_suffix(".csv.tmp")
    df.to_csv(tmp, index=False)
    os.replace(tmp, csv_path)
    pq = CampaignFiles(results).results_parquet
    tmp = pq.with_suffix(".parquet.tmp")
    df.to_parquet(tmp, index=False)
    os.replace(tmp, pq)
    return csv_path
