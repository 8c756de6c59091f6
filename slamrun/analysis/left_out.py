"""Who a view leaves out, and why: every table and figure of a dataset section shows the section's methods, or says
in one line under it which it leaves out (no figure for this metric: KITTI's segments on a track under 100 m; every
run failed, lost under min_coverage, diverged; removed as outliers)."""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable

import numpy as np
import pandas as pd

from slamrun.results.catalogue import DIVERGED, LABELS, LOW_COVERAGE, TUM_MONO, metric_of
from slamrun.results.marks import flags
from slamrun.results.vocabulary import INFRA_FAILURES, UNDER_MIN_COVERAGE


def family(column: str) -> str:
    """The name a run's message gives the problem of the metric that fills `column` (metric_table.campaign_figures:
    "kitti: ...", "rpe: ..."): ate, rpe, kitti, or `evaluation` for a metric that judges the estimate (TUM-Mono's)."""
    metric = metric_of(column)
    return metric if metric and metric != TUM_MONO else "evaluation"


def why_no_figure(runs: pd.DataFrame, metric: str) -> str:
    """Why one method's runs give no figure of `metric` (empty when one of its done runs has one)."""
    status = runs["status"] if "status" in runs.columns else pd.Series("done", index=runs.index)
    done = runs[status == "done"]
    if metric in done.columns and np.isfinite(done[metric].to_numpy(float)).any():
        return ""
    if done.empty:
        failure = runs["failure"] if "failure" in runs.columns else pd.Series(None, index=runs.index)
        charged = runs[(status == "failed") & ~failure.isin(INFRA_FAILURES)]
        if charged.empty:
            return "no finished run yet (pending, or infrastructure failures only)"
        kinds = Counter(_failure_kind(f, m) for f, m in zip(charged["failure"], _messages(charged), strict=True))
        return "every run failed (" + ", ".join(f"{k} {n}" for k, n in kinds.most_common()) + ")"
    reasons = [_reason(m, family(metric)) for m in _messages(done)]
    reason = next((r for r in reasons if r), "")
    return f"no figure in its {len(done)} done run(s)" + (f": {reason}" if reason else "")


def _messages(runs: pd.DataFrame) -> list[str]:
    if "message" not in runs.columns:
        return [""] * len(runs)
    return [m if isinstance(m, str) else "" for m in runs["message"]]


def _failure_kind(failure, message: str) -> str:
    if failure == "lost" and UNDER_MIN_COVERAGE in message:
        return "lost under min_coverage"
    return str(failure) if failure == failure and failure is not None else "failed"


def _reason(message: str, name: str) -> str:
    """The part of a run's message about the metric `name` ("kitti: the ground truth's path (35.2 m) is shorter than
    100 m: no segment"), or ''."""
    for part in message.split("; "):
        part = part.removeprefix("too few poses to evaluate (").rstrip(")")
        if part.startswith(f"{name}: ") or (name == "evaluation" and part.startswith("evaluation ")):
            return part.split(": ", 1)[1] if ": " in part else part
    return ""


def reasons(section: pd.DataFrame, shown, metrics: Iterable[str], group: str = "method") -> dict[str, str]:
    """Each method of `section` (a dataset's runs) that a view of `metrics` does not show, and why (per metric where
    the reasons differ). `shown`: the methods the view shows, or per metric the methods it shows of that metric. A
    method with figures that the view still leaves out had every run removed as an outlier."""
    metrics = [m for m in metrics if m in section.columns]
    if group not in section.columns or not metrics:
        return {}
    if not isinstance(shown, dict):
        shown = dict.fromkeys(metrics, shown)
    shown = {m: {str(g) for g in shown.get(m, ())} for m in metrics}
    out = {}
    for method, runs in section.groupby(group, sort=True):
        missing = [m for m in metrics if str(method) not in shown[m]]
        if not missing:
            continue
        by_reason: dict[str, list[str]] = {}
        for m in missing:
            why = why_no_figure(runs, m) or "its runs were removed as multivariate outliers"
            by_reason.setdefault(why, []).append(LABELS.get(m, m))
        if len(by_reason) == 1 and len(missing) == len(metrics):
            out[str(method)] = next(iter(by_reason))
        else:
            out[str(method)] = "; ".join(f"{', '.join(ms)}: {why}" for why, ms in by_reason.items())
    return out


def left_out(section: pd.DataFrame, shown, metrics: Iterable[str], group: str = "method") -> str:
    """`reasons` as the one line under a view: '' where it shows every method."""
    found = reasons(section, shown, metrics, group)
    return ("Not shown: " + "; ".join(f"{m} ({why})" for m, why in found.items()) + ".") if found else ""


def shown_in(table: pd.DataFrame, metrics: Iterable[str], group: str = "method") -> dict[str, set[str]]:
    """Per metric, the methods a table (a row per method) gives a figure of."""
    out = {}
    for m in metrics:
        if m in table.columns and group in table.columns:
            values = pd.to_numeric(table[m], errors="coerce").to_numpy(float)
            out[m] = {str(g) for g, v in zip(table[group], values, strict=True) if np.isfinite(v)}
    return out


def section_flags(section: pd.DataFrame, group: str = "method") -> dict:
    """Per method of a dataset's runs, its done runs' flags (results.marks.flags): low coverage, diverged."""
    if group not in section.columns or section.empty:
        return {}
    status = section["status"] if "status" in section.columns else pd.Series("done", index=section.index)
    cols = [c for c in (LOW_COVERAGE, DIVERGED, "eval_settings") if c in section.columns]
    runs = section[cols].assign(method=section[group].astype(str).to_numpy(), done=status.eq("done").to_numpy())
    return flags(runs.to_dict("records"))
