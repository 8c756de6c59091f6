"""The study's tables as DataFrames, and their CSV, Markdown and LaTeX forms."""

from __future__ import annotations

import numpy as np
import pandas as pd

from slamrun.analysis.load import counted
from slamrun.analysis.stats import StudyStats, wilcoxon_rank_sum_p
from slamrun.results.catalogue import (
    BUSY_THREADS,
    COVERAGE,
    CPU_WAIT_PCT,
    MAIN_METRICS,
    RESOURCES_TABLE,
    RUNNABLE_THREADS,
    column,
)
from slamrun.results.vocabulary import played

LETTERS = " letters"  # the suffix of a medians column's letter groups
KRUSKAL_ROWS = ("Kruskal-Wallis chi2", "Kruskal-Wallis df", "Kruskal-Wallis p")


def medians_with_letters(st: StudyStats, metrics: list[str]) -> pd.DataFrame:
    """Table 3/4 layout, numeric: one row per method with a figure of any of `metrics` (best first by the first
    metric, then the next) with the runs counted (copies once, those with a figure of any of the metrics), the median
    coverage of those runs, and per metric its median (NaN where the method has no figure of it: left_out says why)
    and, in a column of its own, its letter groups; last rows: the Kruskal-Wallis chi-square, degrees of freedom and
    p-value of each metric."""
    shown = {g for m in metrics for g in st.metrics[m].medians}
    methods = sorted(shown, key=lambda g: (tuple(st.metrics[m].medians.get(g, np.inf) for m in metrics), g))
    kept = st.kept
    rows = []
    for m in methods:
        runs = kept[kept["method"] == m] if "method" in kept.columns else kept.iloc[0:0]
        runs = runs[np.isfinite(runs[metrics].to_numpy(float)).any(axis=1)]
        row: dict = {"method": m, "runs": len(runs)}
        if COVERAGE in kept.columns:
            row[COVERAGE] = float(runs[COVERAGE].median()) if runs[COVERAGE].notna().any() else np.nan
        for metric in metrics:
            s = st.metrics[metric]
            row[metric] = s.medians.get(m, np.nan)
            row[metric + LETTERS] = s.letters.get(m, "")
        rows.append(row)
    for name, value in zip(KRUSKAL_ROWS, ("kruskal_chi2", "kruskal_df", "kruskal_p"), strict=True):
        rows.append({"method": name, **{k: float(getattr(st.metrics[k], value)) for k in metrics}})
    return pd.DataFrame(rows)


def tests_table(st: StudyStats) -> pd.DataFrame:
    """Per metric every test of the procedure with its statistic and p-value: Kruskal-Wallis, Levene, and
    Lilliefors per method; where a test gave none, why."""
    rows = []
    for metric, s in st.metrics.items():
        row = {
            "metric": metric,
            "Kruskal-Wallis chi2": s.kruskal_chi2,
            "df": s.kruskal_df,
            "Kruskal-Wallis p": s.kruskal_p,
            "Levene F": s.levene_F,
            "Levene p": s.levene_p,
        }
        row |= {f"Lilliefors p, {m}": p for m, p in s.lilliefors_p.items()}
        row["no figure because"] = "; ".join(f"{test}: {why}" for test, why in s.notes.items()) or "-"
        rows.append(row)
    return pd.DataFrame(rows)


def pairwise_table(st: StudyStats, adjust: str = "holm", alpha: float = 0.05) -> pd.DataFrame:
    """Per metric and pair of methods: the Wilcoxon rank-sum p adjusted as the letters are, unadjusted, and
    whether the pair differs at `alpha` (adjusted p), in words."""
    rows = []
    for metric, s in st.metrics.items():
        raw = {(r["a"], r["b"]): r["p"] for r in s.pairwise_none}
        for r in s.pairwise_adjusted or s.pairwise_holm:
            p = r["p"]
            rows.append(
                {
                    "metric": metric,
                    "method a": r["a"],
                    "method b": r["b"],
                    f"p ({adjust})": p,
                    "p (unadjusted)": raw.get((r["a"], r["b"]), np.nan),
                    f"different at {alpha:g}": _words(p < alpha) if np.isfinite(p) else "not known",
                }
            )
    return pd.DataFrame(rows)


def _words(different: bool) -> str:
    return "yes" if different else "no"


def resources_table(df: pd.DataFrame, contention_pct: float | None = None) -> pd.DataFrame:
    """Table 2 layout: mean resources per method over its runs; with `contention_pct`, how many of them waited for a
    CPU longer than that share of their wall time beyond the wait they cause themselves (cpu_wait_own_pct: their
    FPS and CPU figures taken under contention)."""
    cols = {c: column(c).heading for c in RESOURCES_TABLE}
    present = [c for c in cols if c in df.columns]
    out = df.groupby("method")[present].mean().reset_index().rename(columns=cols)
    out.insert(1, "runs", df.groupby("method").size().to_numpy())
    if contention_pct is not None and CPU_WAIT_PCT in df.columns:
        own = df["cpu_wait_own_pct"].fillna(0.0) if "cpu_wait_own_pct" in df.columns else 0.0
        over = (df[CPU_WAIT_PCT] - own > contention_pct).groupby(df["method"]).sum()
        out[f"runs with CPU wait > {contention_pct:g} %"] = over.reindex(out["method"]).to_numpy()
    return out


def contended_runs_table(df: pd.DataFrame) -> pd.DataFrame:
    """The runs with an attempt lost under contention (retried, or recorded `contended`): which run, how many such
    attempts, how it ended, and the last such attempt's wait. Empty where there is none."""
    if "contended_attempts" not in df.columns:
        return pd.DataFrame()
    hit = df[df["contended_attempts"].fillna(0) > 0]
    if hit.empty:
        return pd.DataFrame()
    where = hit["direction"].astype(str)
    if "perturbation" in hit.columns:
        where = [played(d, k, lv) for d, k, lv in zip(where, hit["perturbation"], hit.get("level"), strict=True)]
    return pd.DataFrame(
        {
            "method": hit["method"].to_numpy(),
            "sequence": hit["sequence"].to_numpy(),
            "direction": list(where),
            "trial": hit["trial"].to_numpy(),
            "contended attempts": hit["contended_attempts"].astype(int).to_numpy(),
            "ended": [f if s == "failed" else s for s, f in zip(hit["status"], hit["failure"], strict=True)],
            "last contended attempt": [_after_key(m) for m in hit.get("contended_message", [""] * len(hit))],
        }
    ).sort_values(["method", "sequence", "direction", "trial"])


def _after_key(message) -> str:
    """A run's message without the run's key it starts with."""
    text = "" if message is None or (isinstance(message, float) and np.isnan(message)) else str(message)
    return text.split(": ", 1)[1] if ": " in text else text


def motion_bias_table(df: pd.DataFrame, metric: str = MAIN_METRICS[0]) -> pd.DataFrame:
    """Forward vs backward medians per method, with the Wilcoxon rank-sum p-value between directions, over the runs
    `counted` (done, with a figure, copies of a run once: identical trials are one sample, not several)."""
    rows = []
    for m, g in counted(df, metric).groupby("method", sort=True):
        fw = g.loc[g.direction == "forward", metric].to_numpy(float)
        bw = g.loc[g.direction == "backward", metric].to_numpy(float)
        p = wilcoxon_rank_sum_p(fw, bw) if len(fw) and len(bw) else np.nan
        rows.append(
            {
                "method": m,
                "n forward": len(fw),
                "n backward": len(bw),
                f"median {metric} forward": np.median(fw) if len(fw) else np.nan,
                f"median {metric} backward": np.median(bw) if len(bw) else np.nan,
                "p (rank-sum)": p,
            }
        )
    return pd.DataFrame(rows)


def reproduction_table(df: pd.DataFrame, metric: str) -> pd.DataFrame:
    """Imported labels (`source:method`, e.g. study:dso) beside the campaign's own runs of `method`: the medians of
    `metric` over the runs `counted` (copies once), and whether they differ (Wilcoxon rank-sum, alpha 0.05)."""
    rows = []
    runs = counted(df, metric)
    labels = set(df.method.dropna().astype(str))
    for published in sorted(lab for lab in labels if ":" in lab):
        own = published.split(":", 1)[1]
        if own not in labels:
            continue
        new = runs.loc[(runs.method == own), metric].to_numpy(float)
        old = runs.loc[(runs.method == published), metric].to_numpy(float)
        p = wilcoxon_rank_sum_p(new, old) if len(new) and len(old) else np.nan
        rows.append(
            {
                "method": own,
                "published as": published,
                f"median {metric} (new)": np.median(new) if len(new) else np.nan,
                f"median {metric} (published)": np.median(old) if len(old) else np.nan,
                "n new": len(new),
                "n published": len(old),
                "p (rank-sum)": p,
                "different at 0.05": _words(p < 0.05) if np.isfinite(p) else "not known",
            }
        )
    return pd.DataFrame(rows)


def per_sequence_table(df: pd.DataFrame, metric: str = MAIN_METRICS[0]) -> pd.DataFrame:
    """Median of a metric per method (rows) and sequence (columns), over the runs `counted` (done, copies once)."""
    d = counted(df, metric)
    if d.empty:
        return pd.DataFrame()
    return d.pivot_table(index="method", columns="sequence", values=metric, aggfunc="median").reset_index()


def more_threads_than_declared(df: pd.DataFrame, slack: float = 0.5) -> list[str]:
    """One line per method whose runs kept more threads runnable on average than it declares it keeps busy (by more
    than `slack`): its lanes were sized by the declaration, and its own wait beyond its CPUs counted as its own."""
    if RUNNABLE_THREADS not in df.columns or BUSY_THREADS not in df.columns:
        return []
    out = []
    for method, g in df.groupby("method", sort=True):
        runnable = pd.to_numeric(g[RUNNABLE_THREADS], errors="coerce").median()
        declared = pd.to_numeric(g[BUSY_THREADS], errors="coerce").median()
        if np.isfinite(runnable) and np.isfinite(declared) and runnable > declared + slack:
            out.append(
                f"{method} kept {runnable:.1f} threads runnable on average, declared {declared:g}: its lanes were "
                "sized for fewer, and the wait of its own threads beyond its CPUs is counted as its own, never as "
                "the machine's load"
            )
    return out
