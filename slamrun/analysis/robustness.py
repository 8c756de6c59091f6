"""Robustness: how each method's success rate and accuracy change with a perturbation's level (a campaign with
`perturbations:`). Pure tables from a results table; the figures are in slamrun.analysis.figures. Within one
dataset, as every other table: the baseline (the ordinary view) is each kind's first level.

Paired against each method's own baseline: every perturbed run beside the same method's run of the same sequence,
direction and trial on the ordinary view; its figure over the baseline's is the pair's ratio, a failure of the
method's own is a ratio at infinity (counted, never dropped), and the area under the cumulative curve of the ratios
from 1 to AREA_BOUND (log scale) sums a level up in [0, 1], as ETH3D's SLAM benchmark ranks methods by the area
under their cumulative error curves."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from slamrun.analysis.load import evaluated
from slamrun.analysis.stats import study_statistics
from slamrun.analysis.tables import medians_with_letters
from slamrun.results.summary import tally
from slamrun.results.vocabulary import NONE, level_text

BREAKDOWN_PCT = 50.0  # the success rate under which a method is said to break down at a level
AREA_BOUND = 10.0  # the area is over paired ratios 1..AREA_BOUND: 1 unharmed (or better), 0 failed or 10x worse
PAIR_KEY = ("method", "sequence", "direction", "trial")  # what a perturbed run shares with its baseline run


def baseline(df: pd.DataFrame) -> pd.DataFrame:
    """The runs on ordinary views (every run of a table without the axis): what every table but the robustness
    section is made of, so a perturbed run never enters the study's statistics."""
    if "perturbation" not in df.columns:
        return df
    return df[df["perturbation"].fillna(NONE) == NONE]


def perturbed(df: pd.DataFrame) -> bool:
    return "perturbation" in df.columns and bool((df["perturbation"].fillna(NONE) != NONE).any())


def kinds(df: pd.DataFrame) -> list[str]:
    """The perturbations of the table (a kind, or a kind with its schedule: `gaussian_noise@burst:3/10`), in the
    order of slamrun.datasets.perturb.KINDS, each kind's static form first."""
    from slamrun.datasets.perturb import KINDS

    found = set(df["perturbation"].dropna()) - {NONE} if "perturbation" in df.columns else set()
    order = list(KINDS)
    known = [f for f in found if f.partition("@")[0] in KINDS]
    return sorted(known, key=lambda f: (order.index(f.partition("@")[0]), f))


def levels(df: pd.DataFrame, kind: str) -> list[float]:
    """The kind's levels in the table, mildest first (by the kind's severity)."""
    from slamrun.datasets.perturb import kind_of

    found = {float(v) for v in df.loc[df["perturbation"] == kind, "level"].dropna()}
    return sorted(found, key=lambda v: (kind_of(kind).severity_of(v), v))


def series(df: pd.DataFrame, kind: str) -> list[tuple[str, pd.DataFrame]]:
    """(level name, its runs) for the baseline and each level of `kind`, mildest first."""
    out = [(NONE, baseline(df))]
    part = df[df["perturbation"] == kind]
    for level in levels(df, kind):
        out.append((level_text(level), part[part["level"].astype(float) == level]))
    return out


def success_rates(df: pd.DataFrame) -> pd.DataFrame:
    """Per method, kind and level (the baseline as level `none` of each kind): runs, the method's results, done, and
    the success rate over its results (infrastructure failures and unfinished runs left out, as everywhere)."""
    rows = []
    for kind in kinds(df):
        for name, part in series(df, kind):
            for method, runs in part.groupby("method", sort=True):
                t = tally(zip(runs["status"], runs["failure"], runs["eval_status"], strict=True))
                rows.append(
                    {
                        "perturbation": kind,
                        "level": name,
                        "method": method,
                        "runs": t.runs,
                        "results": t.results,
                        "done": t.done,
                        "success %": np.nan if t.success_pct is None else round(t.success_pct, 1),
                    }
                )
    return pd.DataFrame(rows, columns=["perturbation", "level", "method", "runs", "results", "done", "success %"])


def breakdown_table(rates: pd.DataFrame) -> pd.DataFrame:
    """Per method and kind, the mildest level at which its success rate falls under BREAKDOWN_PCT: the level, or
    `never` (every level tested stayed at or above it), or `baseline` (already under it on the ordinary view)."""
    if rates.empty:
        return pd.DataFrame(columns=["method"])
    out: dict[str, dict] = {}
    for (kind, method), part in rates.groupby(["perturbation", "method"], sort=False):
        found = "never"
        for name, rate in zip(part["level"], part["success %"], strict=True):
            if not math.isnan(rate) and rate < BREAKDOWN_PCT:
                found = "baseline" if name == NONE else name
                break
        out.setdefault(method, {"method": method})[_column(kind)] = found
    return pd.DataFrame(sorted(out.values(), key=lambda r: r["method"]))


def _column(kind: str) -> str:
    from slamrun.datasets.perturb import kind_of

    return f"{kind} ({kind_of(kind).parameter})"


def spread(df: pd.DataFrame, kind: str, metric: str) -> pd.DataFrame:
    """Per method and level of `kind` (baseline first): the median, first and third quartiles of `metric` over the
    method's evaluated runs (the spread over trials, sequences and directions), and how many runs gave it."""
    rows = []
    for i, (name, part) in enumerate(series(df, kind)):
        ok = evaluated(part, [metric])
        for method, runs in ok.groupby("method", sort=True):
            v = runs[metric].astype(float)
            rows.append(
                {
                    "method": method,
                    "position": i,
                    "level": name,
                    "median": float(v.median()),
                    "q1": float(v.quantile(0.25)),
                    "q3": float(v.quantile(0.75)),
                    "n": len(v),
                }
            )
    return pd.DataFrame(rows, columns=["method", "position", "level", "median", "q1", "q3", "n"])


def level_statistics(
    df: pd.DataFrame, metrics: list[str], level: float = 0.999, adjust: str = "holm", alpha: float = 0.05
) -> tuple[pd.DataFrame, dict]:
    """The study's procedure within each perturbation level (as within each dataset: a level's runs are one
    population, never pooled with another's): per level, each method's runs, medians and letter groups, and the
    Kruskal-Wallis p of each metric; and the full statistics per level (JSON). Levels with fewer than two methods
    with evaluated runs have none."""
    tables, full = [], {}
    for kind in kinds(df):
        for name, part in series(df, kind)[1:]:
            ok = evaluated(part, metrics)
            if ok.method.nunique() < 2 or len(ok) <= len(metrics) + 1:
                continue
            st = study_statistics(ok, metrics, level=level, adjust=adjust, alpha=alpha)
            table = medians_with_letters(st, metrics)
            table.insert(0, "level", name)
            table.insert(0, "perturbation", kind)
            tables.append(table)
            full[f"{kind}-{name}"] = st.to_json()
    return (pd.concat(tables, ignore_index=True) if tables else pd.DataFrame()), full


def run_errors(df: pd.DataFrame, metric: str) -> pd.Series:
    """Per run: its `metric`, inf for a failure of the method's own (it ran and failed), NaN for no result
    (an infrastructure failure, an unfinished run, a done run without this figure)."""
    from slamrun.results.vocabulary import INFRA_FAILURES

    value = pd.to_numeric(df[metric], errors="coerce") if metric in df.columns else pd.Series(np.nan, df.index)
    value = value.where(np.isfinite(value))
    failed = (df["status"] == "failed") & ~df["failure"].isin(INFRA_FAILURES)
    return value.where(df["status"] == "done", np.where(failed, np.inf, np.nan))


def pairs(df: pd.DataFrame, kind: str, metric: str) -> pd.DataFrame:
    """Each run on a view of `kind` with a result, beside its baseline run (PAIR_KEY): level (text), the key,
    baseline, value (inf: the method failed) and ratio; baseline and ratio NaN where the baseline run has no figure
    (it failed, or is missing): such a run makes no pair."""
    cols = ["level", *PAIR_KEY, "baseline", "value", "ratio"]
    base = baseline(df)
    base = base.assign(baseline=run_errors(base, metric))
    base = base[np.isfinite(base["baseline"])].drop_duplicates(list(PAIR_KEY))[[*PAIR_KEY, "baseline"]]
    part = df[df["perturbation"] == kind]
    part = part.assign(value=run_errors(part, metric), level=part["level"].astype(float).map(level_text))
    part = part[part["value"].notna()]
    if part.empty:
        return pd.DataFrame(columns=cols)
    joined = part[["level", *PAIR_KEY, "value"]].merge(base, on=list(PAIR_KEY), how="left")
    joined["ratio"] = joined["value"] / joined["baseline"]
    return joined[cols]


def area(ratios: np.ndarray, bound: float = AREA_BOUND) -> float:
    """The area under the cumulative curve of paired ratios from 1 to `bound` on a log axis, over its width: the
    mean over pairs of the share of [1, bound] in which the pair is counted (1 for a ratio at most 1, 0 for one at
    `bound` or beyond, a failure's inf included). NaN for no pairs."""
    r = np.asarray(ratios, float)
    if r.size == 0:
        return math.nan
    share = 1.0 - np.log(np.maximum(r, 1.0)) / math.log(bound)
    return float(np.clip(share, 0.0, 1.0).mean())


PAIRED_COLUMNS = ["perturbation", "level", "method", "pairs", "failed", "without baseline", "median ratio", "area"]


def paired_table(df: pd.DataFrame, metric: str, only: str | None = None) -> pd.DataFrame:
    """Per kind (`only` that one), level (mildest first) and method: the pairs, how many the method failed, the runs
    without a baseline figure, the median ratio (failures at infinity: inf when half or more failed) and the area."""
    rows = []
    for kind in [k for k in kinds(df) if only in (None, k)]:
        p = pairs(df, kind, metric)
        for name, _ in series(df, kind)[1:]:
            at = p[p["level"] == name]
            for method, runs in at.groupby("method", sort=True):
                r = runs["ratio"].to_numpy(float)
                ok = r[~np.isnan(r)]
                rows.append(
                    {
                        "perturbation": kind,
                        "level": name,
                        "method": method,
                        "pairs": len(ok),
                        "failed": int(np.isinf(ok).sum()),
                        "without baseline": int(np.isnan(r).sum()),
                        "median ratio": float(np.median(ok)) if len(ok) else math.nan,
                        "area": area(ok),
                    }
                )
    return pd.DataFrame(rows, columns=PAIRED_COLUMNS)


def summary_table(df: pd.DataFrame, metric: str) -> pd.DataFrame:
    """Per method, for each kind: its area (the mean of its levels' areas, each level weighing alike) and the
    level at which it breaks down (breakdown_table)."""
    paired, broken = paired_table(df, metric), breakdown_levels(success_rates(df))
    out: dict[str, dict] = {}
    for kind in kinds(df):
        areas = paired[paired["perturbation"] == kind].groupby("method")["area"].mean()
        for method in sorted(set(df["method"])):
            row = out.setdefault(method, {"method": method})
            row[f"{kind} area"] = float(areas.get(method, math.nan))
            row[f"{kind} breakdown"] = broken.get((kind, method), "")
    return pd.DataFrame(list(out.values()))


def breakdown_levels(rates: pd.DataFrame) -> dict[tuple[str, str], str]:
    """breakdown_table's levels by (kind, method)."""
    table = breakdown_table(rates)
    return {
        (kind, m): level
        for kind in dict.fromkeys(rates["perturbation"]) if _column(kind) in table
        for m, level in zip(table["method"], table[_column(kind)], strict=True) if isinstance(level, str)
    }  # fmt: skip


def long_table(df: pd.DataFrame, metric: str, dataset: str = "") -> pd.DataFrame:
    """One row per kind, level and method of one dataset (the baseline as level `none` of each kind): its success
    rate with its counts, its paired figures against the baseline on `metric`, and the method's breakdown level of
    the kind: results/robustness.csv."""
    rates = success_rates(df)
    paired = paired_table(df, metric)
    out = rates.merge(paired, on=["perturbation", "level", "method"], how="left")
    out.insert(0, "dataset", dataset)
    out["metric"] = metric
    broken = breakdown_levels(rates)
    out["breakdown"] = [broken.get(km, "") for km in zip(out["perturbation"], out["method"], strict=True)]
    return out
