"""The per-method summary of a results table: counts, rates and medians, one row per method label.

Built on slamrun.results.summary's tally, so the terminal table at the end of a campaign, `slamrun status`
and the report's table give the same counts and rates: infrastructure failures and unfinished runs are left
out of every rate; medians are over the evaluated runs (done, and evaluated ok), as in the statistics.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from slamrun.analysis.load import by_dataset, counted, main_metric
from slamrun.results.catalogue import FPS, SUMMARY_METRICS
from slamrun.results.summary import tally
from slamrun.results.vocabulary import INFRA_FAILURES, METHOD_FAILURES

POOLED_COLUMNS = ("method", "runs", "done", "failed", "infra", "pending", "success_pct", "failure_pct")


def method_summary(df: pd.DataFrame) -> pd.DataFrame:
    """Per method: runs, done, failed (the method's), infra, pending, success and failure rates over the
    method's results, evaluated and not evaluable runs, each failure kind, and medians of the main metrics over the
    runs `counted` (done, with a figure of that metric, copies once, as in the statistics) and of fps."""
    rows = []
    for method, g in df.groupby("method", sort=False):
        status = g["status"] if "status" in g.columns else ["done"] * len(g)  # a table of observations: results
        t = tally(zip(status, _text(g, "failure"), _text(g, "eval_status"), strict=True))
        row = {
            "method": method,
            "runs": t.runs,
            "done": t.done,
            "failed": t.failed,
            "infra": t.infra,
            "contended": t.contended,  # of the infra failures: lost while waiting for a CPU (counted apart)
            "pending": t.pending,
            "success_pct": np.nan if t.success_pct is None else t.success_pct,
            "failure_pct": np.nan if t.failure_pct is None else t.failure_pct,
            "evaluated": t.evaluated,
            "not_evaluable": t.not_evaluable,
            **{kind: t.failures.get(kind, 0) for kind in METHOD_FAILURES},
        }
        for m in SUMMARY_METRICS:  # over the runs the statistics count: done, with a figure, copies once
            values = counted(g, m)[m] if m in g.columns else pd.Series(dtype=float)
            row[f"median_{m}"] = values.median() if len(values) else np.nan
        row["median_fps"] = g[FPS].median() if FPS in g.columns and g[FPS].notna().any() else np.nan
        rows.append(row)
    return pd.DataFrame(rows)


def _text(g: pd.DataFrame, column: str) -> list[str | None]:
    """A text column's values, None where it is empty or absent (CSV gives NaN)."""
    if column not in g.columns:
        return [None] * len(g)
    return [v if isinstance(v, str) else None for v in g[column]]


def ranked_by(df: pd.DataFrame) -> dict[str, str]:
    """Per dataset, the accuracy figure its sequences rank the methods by (e_align, else ATE RMSE)."""
    return {name: m for name, part in by_dataset(df).items() if (m := main_metric(part)) is not None}


def sequence_ranks(df: pd.DataFrame) -> pd.DataFrame:
    """Per dataset, sequence and method: the method's median of the dataset's accuracy figure over its evaluated
    runs, and its rank among the methods with results on that sequence (1 best, ties averaged; a method with
    results but no evaluated run shares the last rank). Ranks are unitless: they pool across datasets."""
    rows = []
    for name, part in by_dataset(df).items():
        metric = main_metric(part)
        if metric is None:
            continue
        results = part
        if "status" in part.columns:
            failure = part["failure"] if "failure" in part.columns else pd.Series(None, index=part.index)
            results = part[(part["status"] == "done") | ((part["status"] == "failed") & ~failure.isin(INFRA_FAILURES))]
        medians = counted(part, metric).groupby(["sequence", "method"])[metric].median()
        for sequence, g in results.groupby("sequence", sort=True):
            methods = sorted(g["method"].astype(str).unique())
            values = [medians.get((sequence, m), np.nan) for m in methods]
            if all(np.isnan(values)):
                continue  # nothing to rank by
            ranks = pd.Series([np.inf if np.isnan(v) else v for v in values]).rank(method="average").to_numpy()
            for m, v, r in zip(methods, values, ranks, strict=True):
                rows.append(
                    {"dataset": name, "sequence": sequence, "method": m, "metric": metric, "median": v, "rank": r}
                )
    return pd.DataFrame(rows, columns=["dataset", "sequence", "method", "metric", "median", "rank"])


def pooled_summary(df: pd.DataFrame) -> pd.DataFrame:
    """Per method over every dataset: the counts and rates of method_summary (unitless, so sound to pool) and its
    mean rank within sequences (sequence_ranks) with how many sequences ranked it; no median in metres."""
    s = method_summary(df)
    if s.empty:
        return pd.DataFrame(columns=[*POOLED_COLUMNS, "mean_rank", "sequences_ranked"])
    s = s[list(POOLED_COLUMNS)].copy()
    ranks = sequence_ranks(df).groupby("method")["rank"]
    s["mean_rank"] = s["method"].astype(str).map(ranks.mean())
    s["sequences_ranked"] = s["method"].astype(str).map(ranks.size()).fillna(0).astype(int)
    return s
