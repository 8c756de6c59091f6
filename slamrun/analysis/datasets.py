"""The study's procedure within each dataset of a campaign, and the one view across datasets that is sound to pool:
success rates and the methods' ranks within each sequence. No value in metres is pooled: EuRoC's room and KITTI's
drive are not one population."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from slamrun.analysis.left_out import reasons, section_flags
from slamrun.analysis.load import by_dataset, evaluated, metrics_for, one_dataset
from slamrun.analysis.stats import StudyStats, screen, study_statistics
from slamrun.analysis.summary import pooled_summary, ranked_by
from slamrun.errors import SlamRunError
from slamrun.results.catalogue import MAIN_METRICS

POOLED_NOTE = (
    "pooled over the datasets: counts and success rates of every run, and each method's rank within each sequence "
    "(by that dataset's accuracy figure, averaged over the sequences; a method with results but no evaluated run on "
    "a sequence shares the last rank); no value in metres is pooled"
)


def dataset_metrics(part: pd.DataFrame, name: str, chosen: list[str] | None, source: Path) -> list[str]:
    """The metrics of one dataset's statistics: `chosen`, each of which its runs must have values of, else the
    metrics its runs have (metrics_for)."""
    if chosen is None:
        return metrics_for(part)
    missing = [m for m in chosen if m not in part.columns]
    if missing:
        raise SlamRunError(f"{source}: no column(s) {', '.join(missing)}; have {', '.join(map(str, part.columns))}")
    empty = [m for m in chosen if not part[m].notna().any()]
    if empty:
        raise SlamRunError(
            f"{source}: dataset {name!r} has no value of {', '.join(empty)}; its metrics: "
            f"{', '.join(metrics_for(part)) or 'none'}; choose metrics it has, or another dataset with --dataset"
        )
    return list(chosen)


def dataset_rows(df: pd.DataFrame, dataset: str | None, source: Path) -> pd.DataFrame:
    """The rows of the dataset named `dataset` (all rows for None); an unknown name is an error listing the known."""
    if dataset is None:
        return df
    return one_dataset(by_dataset(df), dataset, source)[dataset]


def per_dataset_statistics(
    df: pd.DataFrame,
    source: Path,
    metrics: list[str] | None = None,
    level: float = 0.999,
    adjust: str = "holm",
    alpha: float = 0.05,
) -> dict[str, StudyStats]:
    """The study's procedure (outliers, normality, variance, Kruskal-Wallis, pairwise tests, letters) on each
    dataset's evaluated runs alone, by dataset name. A figure that is no measurement (stats.screen: infinite, a
    negative error, beyond stats.LIMIT) is left out of its metric's tests and named (`StudyStats.excluded`), also
    where it was its run's only figure."""
    groups = by_dataset(df)
    out = {}
    for name, part in groups.items():
        chosen = dataset_metrics(part, name, metrics, source)
        part, excluded = screen(part, chosen)
        st = study_statistics(evaluated(part, chosen), chosen, level=level, adjust=adjust, alpha=alpha)
        st.excluded = excluded  # also the runs whose every figure was no measurement (`evaluated` drops them)
        out[name] = with_left_out(st, part)
    return out


def with_left_out(st: StudyStats, section: pd.DataFrame) -> StudyStats:
    """`st` with, per metric, each method of the dataset's runs (`section`) its tests leave out and why (a method
    whose every figure was no measurement, stats.screen, says how many were left out), and each method's marks (low
    coverage, diverged)."""
    section = screen(section, list(st.metrics))[0]
    st.left_out = {m: reasons(section, set(s.medians), [m]) for m, s in st.metrics.items()}
    for metric, gone in st.left_out.items():
        for method in gone:
            if n := sum(e["metric"] == metric and str(e.get("method")) == method for e in st.excluded):
                gone[method] += f"; {n} figure(s) left out as no measurement"
    st.marks = section_flags(section)
    return st


def pooled_json(df: pd.DataFrame) -> dict:
    """The pooled view of a table as JSON: which datasets, what was pooled, and per method its counts, rates and
    mean rank within sequences (a figure that is no measurement, stats.screen, ranks no method)."""
    summary = pooled_summary(screen(df, [m for m in MAIN_METRICS if m in df.columns])[0])
    methods = {
        str(r["method"]): {k: r[k] for k in summary.columns if k != "method"} for r in summary.to_dict("records")
    }
    return {"datasets": list(by_dataset(df)), "note": POOLED_NOTE, "ranked_by": ranked_by(df), "methods": methods}


def statistics_json(per: dict[str, StudyStats], pooled: dict) -> dict:
    """`slamrun stats --json`: one block of the study's figures per dataset, and the pooled view, labelled."""
    return {"datasets": {name: st.to_json() for name, st in per.items()}, "pooled": pooled}
