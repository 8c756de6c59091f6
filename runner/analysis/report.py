"""The report of a campaign: statistics, tables (CSV, Markdown, LaTeX) and figures (PNG, SVG), gathered in a
self-contained report/index.html; within each dataset (report/datasets/<name>/ when a campaign has several)."""

from __future__ import annotations

import base64
import html
import json
import re
from pathlib import Path

import pandas as pd

from runner.analysis import figures, tables
from runner.analysis.load import NO_DATASET, by_dataset, evaluated, load_results, main_metric, metrics_for
from runner.analysis.stats import study_statistics
from runner.analysis.summary import method_summary, pooled_summary, ranked_by, sequence_ranks
from runner.core import jsonio
from runner.results.vocabulary import LABELS, METHOD_FAILURES, TRAJECTORY_STATS_METRICS

RUNS_COLUMNS = {
    "runs": "runs",
    "done": "done",
    "failed": "failed (method)",
    "infra": "infra",
    "pending": "pending",
    "success_pct": "success %",
    "failure_pct": "failure %",
    "evaluated": "evaluated",
    "not_evaluable": "not evaluable",
}


def runs_table(df: pd.DataFrame) -> pd.DataFrame:
    """The report's runs-and-failures table: the per-method summary's counts and rates (rates over the
    method's results: infrastructure failures and unfinished runs are left out), and each failure kind."""
    s = method_summary(df)
    if s.empty:
        return s
    out = s[["method", *RUNS_COLUMNS, *METHOD_FAILURES]].rename(columns=RUNS_COLUMNS)
    return out.round({"success %": 1, "failure %": 1})


def write_report(
    results: Path, level: float = 0.999, adjust: str = "holm", alpha: float = 0.05, trajectory_sequences: int = 2
) -> Path:
    """report/index.html with its tables and figures. Every statistic, table and figure is of one dataset: a
    campaign of several datasets gets one section (and folder report/datasets/<name>/) per dataset, after the views
    that are sound to pool (counts, success rates, ranks within sequences), labelled as pooled."""
    results = Path(results)
    df = load_results(results)
    out = results / "report"
    groups = by_dataset(df)
    options = {"level": level, "adjust": adjust, "alpha": alpha, "trajectory_sequences": trajectory_sequences}
    if len(groups) == 1:
        name, part = next(iter(groups.items()))
        sections, figs = dataset_report(part, out, name if name != NO_DATASET else "", **options)
        intro = f"<p>Dataset: {html.escape(name)}</p>" if name != NO_DATASET else ""
        body = intro + _body(sections, figs, "h2")
    else:
        body = _body(pooled_report(df, out), [], "h2")
        for name, folder in _folders(groups).items():
            sections, figs = dataset_report(groups[name], out / "datasets" / folder, name, **options)
            body += f"<h2>Dataset {html.escape(name)}</h2>" + _body(sections, figs, "h3")
    index = out / "index.html"
    index.parent.mkdir(parents=True, exist_ok=True)
    index.write_text(_html(results.name, body))
    return index


def pooled_report(df: pd.DataFrame, out: Path) -> list[tuple[str, str]]:
    """The sections of a campaign of several datasets that pool them, where pooling is sound: the runs and
    failures per method (counts and rates) and the mean rank of each method within the sequences."""
    tab_dir = out / "tables"
    sections = []
    fails = runs_table(df)
    title = "Runs and failures per method, all datasets (pooled)"
    tables.write_all(fails, tab_dir, "failures", title)
    sections.append((title, tables.to_html(fails)))
    ranks = pooled_summary(df)[["method", "mean_rank", "sequences_ranked"]]
    ranks = ranks.rename(columns={"mean_rank": "mean rank", "sequences_ranked": "sequences"}).round({"mean rank": 2})
    by = ", ".join(f"{d}: {m}" for d, m in ranked_by(df).items())
    title = "Mean rank within sequences, all datasets (pooled)"
    tables.write_all(ranks, tab_dir, "pooled_ranks", f"{title}; ranked by {by}")
    tables.write_all(sequence_ranks(df), tab_dir, "sequence_ranks", "Each method's rank within each sequence")
    note = (
        f"Each sequence ranks its methods by their median ({by}; 1 best, ties share the mean rank; a method with "
        "results but no evaluated run shares the last rank); a method's mean rank is over the sequences it ran. "
        "Every other figure of this report is within one dataset: values in metres of different datasets are not "
        "one population."
    )
    sections.append((title, f"<p>{html.escape(note)}</p>" + tables.to_html(ranks)))
    return sections


def dataset_report(
    df: pd.DataFrame,
    out: Path,
    dataset: str = "",
    level: float = 0.999,
    adjust: str = "holm",
    alpha: float = 0.05,
    trajectory_sequences: int = 2,
) -> tuple[list[tuple[str, str]], list[tuple[Path, str]]]:
    """The study's report of one dataset's runs into `out` (statistics*.json, tables/, figures/): its sections
    (title, html) and figures (file, label). `dataset` labels captions and figure titles."""
    fig_dir, tab_dir = out / "figures", out / "tables"
    where = f" ({dataset})" if dataset else ""
    metrics = metrics_for(df)
    ok = evaluated(df, metrics)
    sections: list[tuple[str, str]] = []

    fails = runs_table(df)
    tables.write_all(fails, tab_dir, "failures", "Runs and failures per method" + where)
    sections.append(("Runs and failures per method", tables.to_html(fails)))

    st = None
    if ok.method.nunique() >= 2 and len(ok) > len(metrics) + 1:
        st = study_statistics(ok, metrics, level=level, adjust=adjust, alpha=alpha)
        out.mkdir(parents=True, exist_ok=True)
        (out / "statistics.json").write_text(jsonio.dumps(st.to_json(), indent=1))
        acc = [m for m in ("e_t", "e_r", "e_s_sym", "e_s") if m in metrics][:3]
        seg = [m for m in ("e_start", "e_end", "e_rmse") if m in metrics]
        trajectory = [m for m in TRAJECTORY_STATS_METRICS if m in metrics]
        note = (
            f"{len(ok)} evaluated runs{where}, {st.n_outliers} multivariate outliers removed (squared Mahalanobis "
            f"distance over {len(metrics)} metrics above {st.cutoff:.4f}, the chi-square {level} quantile); "
            f"letters: pairwise Wilcoxon rank-sum tests, {adjust} adjustment, alpha {alpha}."
        )
        sections.append(("Statistics", f"<p>{html.escape(note)}</p>"))
        for chosen, name, caption, title in (
            (acc, "table3_drift", "Medians of the drift metrics, with letter groups", "Drift (Table 3 layout)"),
            (
                seg,
                "table4_segments",
                "Medians of the segment alignment errors, with letter groups",
                "Segment errors (Table 4 layout)",
            ),
            (
                trajectory,
                "trajectory_metrics",
                "Medians of ATE, RPE and KITTI's errors, with letter groups",
                "ATE, RPE and KITTI's errors",
            ),
        ):
            if chosen:
                table = tables.medians_with_letters(st, chosen)
                tables.write_all(table, tab_dir, name, caption + where)
                sections.append((title, tables.to_html(table)))
        # the same procedure per direction: motion bias can change the ranking
        for direction in ("forward", "backward"):
            part = ok[ok.direction == direction] if "direction" in ok.columns else ok.iloc[0:0]
            if part.method.nunique() < 2 or len(part) <= len(metrics) + 1:
                continue
            sd = study_statistics(part, metrics, level=level, adjust=adjust, alpha=alpha)
            (out / f"statistics_{direction}.json").write_text(jsonio.dumps(sd.to_json(), indent=1))
            td = tables.medians_with_letters(sd, acc or trajectory)
            what = "Drift" if acc else "ATE, RPE and KITTI's errors"
            caption = f"{what} medians, {direction} runs only{where}"
            tables.write_all(td, tab_dir, f"table3_drift_{direction}", caption)
            sections.append((f"{what}, {direction} runs only", tables.to_html(td)))
    else:
        sections.append(("Statistics", "<p>Fewer than two methods with evaluated runs: no group comparison.</p>"))

    res = tables.resources_table(df[df.status.isin(["done", "failed"])]) if "status" in df else pd.DataFrame()
    if not res.empty:
        tables.write_all(res, tab_dir, "table2_resources", "Mean resources per run" + where)
        sections.append(("Resources (Table 2 layout)", tables.to_html(res)))
    # the campaign's accuracy figure per run: TUM-Mono's e_align, else ATE (datasets without TUM-Mono's metrics)
    main = main_metric(df)
    if main is not None and "direction" in df.columns:
        mb = tables.motion_bias_table(df, main)
        tables.write_all(mb, tab_dir, "motion_bias", f"Forward vs backward {main}{where}")
        sections.append(("Motion bias: forward vs backward", tables.to_html(mb)))
        repro = tables.reproduction_table(df[df.status == "done"] if "status" in df else df, main)
        if not repro.empty:
            tables.write_all(repro, tab_dir, "reproduction", f"Reproduction: new runs vs published, {main}{where}")
            sections.append(("Reproduction: new runs vs published", tables.to_html(repro)))
        seq = tables.per_sequence_table(df, main)
        if not seq.empty:
            tables.write_all(seq, tab_dir, f"{main}_per_sequence", f"Median {main} per method and sequence{where}")
            sections.append((f"Median {main} per sequence", tables.to_html(seq)))

    figs: list[Path] = []
    if not ok.empty:
        for m in ("e_t", "e_r", "e_s_sym", "e_start", "e_end", "ate_rmse", "rpe_t_rmse"):
            if m in metrics:
                figs.append(figures.cumulative(ok, m, fig_dir, label=dataset))
        if main is not None:
            figs.append(
                figures.cumulative(ok, main, fig_dir, f"cumulative_{main}_motion_bias", bold_all=True, label=dataset)
            )
            figs.append(figures.heatmap(df, fig_dir, main, label=dataset))
    if st is not None:
        for m in metrics:
            figs.append(figures.boxplot(st, m, fig_dir, label=dataset))
    figs += _trajectory_figures(df, fig_dir, trajectory_sequences, dataset)
    return sections, [(f, dataset) for f in figs]


def _folders(groups: dict[str, pd.DataFrame]) -> dict[str, str]:
    """A folder name per dataset name: its letters, digits, '.', '-' and '_' (others '_'), unique."""
    out: dict[str, str] = {}
    for name in groups:
        base = re.sub(r"[^A-Za-z0-9._-]", "_", name).strip(".") or "dataset"
        folder, k = base, 2
        while folder in out.values():
            folder, k = f"{base}_{k}", k + 1
        out[name] = folder
    return out


def _trajectory_figures(df: pd.DataFrame, folder: Path, n_sequences: int, label: str = "") -> list[Path]:
    """For the first sequences, each method's best, median and worst evaluated run (by ATE where the campaign
    has it, else e_align), drawn over the ground truth."""
    from runner.core.trajectory import read_tum
    from runner.datasets.layouts import open_sequence
    from runner.errors import SlamRunError

    out = []
    metric = next((m for m in ("ate_rmse", "e_align") if m in df.columns and df[m].notna().any()), None)
    if "run_dir" not in df.columns or metric is None:
        return out
    ok = df[df.status == "done"].dropna(subset=[metric]) if "status" in df.columns else df.dropna(subset=[metric])
    for sequence in sorted(ok.sequence.unique())[:n_sequences]:
        runs, gt, full = [], None, None
        for method, g in ok[ok.sequence == sequence].groupby("method"):
            g = g.sort_values(metric)
            picks = {"best": g.iloc[0], "median": g.iloc[(len(g) - 1) // 2], "worst": g.iloc[-1]}
            for which, row in picks.items():
                if which != "best" and row.run_dir == picks["best"].run_dir:
                    continue  # a method with one run: it is all three
                run_dir = Path(row.run_dir)
                try:
                    if gt is None:
                        folder_of_sequence = Path(json.loads((run_dir / "run.json").read_text())["sequence_dir"])
                        gt = open_sequence(folder_of_sequence).groundtruth()
                        full_path = folder_of_sequence / "groundtruth_full.txt"
                        full = read_tum(full_path) if full_path.is_file() else None
                    runs.append((method, which, read_tum(run_dir / "trajectory.txt")))
                except (OSError, KeyError, ValueError, SlamRunError):
                    continue
        if runs and gt is not None:
            out.append(figures.trajectories(runs, gt, full, folder, sequence, metric, label=label))
    return out


def _body(sections: list[tuple[str, str]], figs: list[tuple[Path, str]], heading: str) -> str:
    """Sections under `heading` tags, then the figures (PNG inlined), captioned with their dataset."""
    parts = [f"<{heading}>{html.escape(h)}</{heading}>{body}" for h, body in sections]
    for f, dataset in figs:
        data = base64.b64encode(f.read_bytes()).decode()
        caption = html.escape((f"{dataset}: " if dataset else "") + f.stem.replace("_", " "))
        label = LABELS.get(f.stem.split("_", 1)[-1], "")
        parts.append(
            f'<figure><img alt="{caption}" src="data:image/png;base64,{data}">'
            f"<figcaption>{caption}{(' - ' + html.escape(label)) if label else ''}</figcaption></figure>"
        )
    return "".join(parts)


def _html(title: str, body: str) -> str:
    check = (
        "<script>window.addEventListener('load',()=>{const i=[...document.images];"
        "document.body.dataset.imagesLoaded=i.filter(x=>x.complete&&x.naturalWidth>0).length+'/'+i.length;});"
        "</script>"
    )
    style = (
        "body{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}table{border-collapse:collapse;"
        "margin:1em 0;font-size:13px}td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}"
        "td:first-child,th:first-child{text-align:left}img{max-width:100%}figure{margin:1.5em 0}"
    )
    return (
        f"<!doctype html><html><head><meta charset='utf-8'><title>{html.escape(title)} report</title>"
        f"<style>{style}</style>{check}</head><body><h1>Campaign {html.escape(title)}</h1>" + body + "</body></html>"
    )
