"""Load a campaign's results for analysis: the table, its evaluated runs, the metrics it has."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from slamrun.errors import SlamRunError
from slamrun.results.catalogue import E_S, E_S_SYM, MAIN_METRICS, STUDY_METRICS, TRAJECTORY_STATS_METRICS
from slamrun.results.files import CampaignFiles

NO_DATASET = "all"  # the one dataset of a table without a dataset column (or the name of rows that have none)


def load_results(path: Path) -> pd.DataFrame:
    """results.csv or results.parquet, or a results directory: its ledger when it has one (the truth, also while
    a campaign runs and before its first export), else the table it holds."""
    path = Path(path)
    ledger_path = CampaignFiles(path).ledger
    if path.is_dir() and (ledger_path.exists() or ledger_path.is_symlink()):  # a folder or a FIFO: one line, below
        from slamrun.engine.export import results_frame
        from slamrun.engine.ledger import Ledger

        ledger = Ledger(CampaignFiles(path).ledger, read_only=True)
        try:
            df = results_frame(ledger)
        finally:
            ledger.close()
        if df.empty:
            raise SlamRunError(f"{path}: no run in its ledger yet")
        return df
    if path.is_dir():
        path = CampaignFiles(path).table()
    if not path.exists():
        raise SlamRunError(f"{path}: no results; run `slamrun campaign` first")
    df = pd.read_parquet(path) if path.suffix == ".parquet" else read_csv(path)
    if "method" not in df.columns:
        raise SlamRunError(f"{path}: no 'method' column; expected a slamrun results table")
    return df


# the text columns of a results table: read as text (KITTI's sequence 00 is not the number 0)
TEXT_COLUMNS = ("method", "sequence", "direction", "dataset", "status", "failure", "eval_status", "method_name")


def read_csv(path: Path) -> pd.DataFrame:
    """A results.csv, its text columns as text."""
    return pd.read_csv(path, dtype=dict.fromkeys(TEXT_COLUMNS, str))


def evaluated(df: pd.DataFrame, metrics: list[str]) -> pd.DataFrame:
    """Runs that ended `done` with a figure of at least one of `metrics` (the study's 'blank runs' are the others; a
    run that timed out or got lost is a failure even when it wrote poses that could be evaluated). Each metric's
    views take those of them with a figure for it (`counted`): a run without KITTI's segment figure (a track under
    100 m) stays in ATE's."""
    present = [m for m in metrics if m in df.columns]
    if "status" in df.columns:
        df = df[df["status"] == "done"]
    if not present:
        return df
    return df[np.isfinite(df[present].to_numpy(float)).any(axis=1)]


WITHIN = ("sequence", "direction")  # a copy is a run of the same method, sequence and direction with equal figures


def counted(df: pd.DataFrame, metric: str, group: str = "method") -> pd.DataFrame:
    """The runs every view of `metric` counts: done, with a figure for it, and each distinct figure of a method,
    sequence and direction once (a deterministic method's identical trials are one run, as in the statistics:
    analysis.stats.distinct_runs)."""
    ok = evaluated(df, [metric])
    ok = ok[np.isfinite(ok[metric].to_numpy(float))] if metric in ok.columns else ok.iloc[0:0]
    within = [c for c in WITHIN if c in ok.columns]
    if len(within) < len(WITHIN):
        return ok  # a table of plain observations: every row a sample
    return ok[~ok.duplicated(subset=[group, *within, metric], keep="first")]


def metrics_for(df: pd.DataFrame) -> list[str]:
    """The metrics this table has values of: the study's six (e_s' if present, else e_s), then the ATE, RPE and
    KITTI figures of datasets that ask for them."""

    def has(m: str) -> bool:
        return m in df.columns and bool(df[m].notna().any())

    out = []
    for m in STUDY_METRICS:
        if has(m):
            out.append(m)
        elif m == E_S_SYM and has(E_S):
            out.append(E_S)
    return out + [m for m in TRAJECTORY_STATS_METRICS if has(m)]


def by_dataset(df: pd.DataFrame) -> dict[str, pd.DataFrame]:
    """The table's rows per dataset (the spec's dataset name each run recorded), names sorted: metres of one
    dataset are not a population with another's. A table without a dataset column is one group, NO_DATASET."""
    if "dataset" not in df.columns:
        return {NO_DATASET: df}
    names = df["dataset"].map(lambda v: NO_DATASET if pd.isna(v) or str(v) == "" else str(v))
    return {name: df[names == name] for name in sorted(set(names))}


def one_dataset(groups: dict[str, pd.DataFrame], name: str, source: Path) -> dict[str, pd.DataFrame]:
    """`groups` narrowed to the dataset `name`; an unknown name is an error listing the known ones."""
    if name not in groups:
        raise SlamRunError(f"{source}: no dataset {name!r} in its runs; known: {', '.join(groups)}")
    return {name: groups[name]}


def main_metric(df: pd.DataFrame) -> str | None:
    """The accuracy figure of one run that a table's per-run views use: TUM-Mono's e_align where the runs have it,
    else ATE RMSE (datasets without TUM-Mono's metrics); None where neither has a value."""
    return next((m for m in MAIN_METRICS if m in df.columns and df[m].notna().any()), None)
