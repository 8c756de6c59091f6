"""The per-method summary of a results table: counts, rates and medians, one row per method label.

Built on runner.results.summary's tally, so the terminal table at the end of a campaign, `slamrun status`
and the report's table give the same counts and rates: infrastructure failures and unfinished runs are left
out of every rate; medians are over the evaluated runs (done, and evaluated ok), as in the statistics.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from runner.results.summary import tally
from runner.results.vocabulary import METHOD_FAILURES, SUMMARY_METRICS


def method_summary(df: pd.DataFrame) -> pd.DataFrame:
    """Per method: runs, done, failed (the method's), infra, pending, success and failure rates over the
    method's results, evaluated and not evaluable runs, each failure kind, and medians of the main metrics
    and of fps."""
    rows = []
    for method, g in df.groupby("method", sort=False):
        t = tally(zip(g["status"], _text(g, "failure"), _text(g, "eval_status"), strict=True))
        row = {
            "method": method,
            "runs": t.runs,
            "done": t.done,
            "failed": t.failed,
            "infra": t.infra,
            "pending": t.pending,
            "success_pct": np.nan if t.success_pct is None else t.success_pct,
            "failure_pct": np.nan if t.failure_pct is None else t.failure_pct,
            "evaluated": t.evaluated,
            "not_evaluable": t.not_evaluable,
            **{kind: t.failures.get(kind, 0) for kind in METHOD_FAILURES},
        }
        ok = g[(g["status"] == "done") & (pd.Series(_text(g, "eval_status"), index=g.index) == "ok")]
        for m in SUMMARY_METRICS:
            row[f"median_{m}"] = ok[m].median() if m in ok.columns and len(ok) else np.nan
        row["median_fps"] = g["fps"].median() if "fps" in g.columns and g["fps"].notna().any() else np.nan
        rows.append(row)
    return pd.DataFrame(rows)


def _text(g: pd.DataFrame, column: str) -> list[str | None]:
    """A text column's values, None where it is empty or absent (CSV gives NaN)."""
    if column not in g.columns:
        return [None] * len(g)
    return [v if isinstance(v, str) else None for v in g[column]]
