"""The report of a campaign: statistics, tables (CSV, Markdown, LaTeX) and figures (PNG, SVG), gathered in a
self-contained report/index.html."""

from __future__ import annotations

import base64
import html
import json
from pathlib import Path

import pandas as pd

from runner.analysis import figures, tables
from runner.analysis.load import evaluated, load_results, metrics_for
from runner.analysis.stats import study_statistics
from runner.analysis.summary import method_summary
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
    results = Path(results)
    df = load_results(results)
    out = results / "report"
    fig_dir, tab_dir = out / "figures", out / "tables"
    metrics = metrics_for(df)
    ok = evaluated(df, metrics)
    sections: list[tuple[str, str]] = []

    fails = runs_table(df)
    tables.write_all(fails, tab_dir, "failures", "Runs and failures per method")
    sections.append(("Runs and failures per method", tables.to_html(fails)))

    st = None
    if ok.method.nunique() >= 2 and len(ok) > len(metrics) + 1:
        st = study_statistics(ok, metrics, level=level, adjust=adjust, alpha=alpha)
        (out / "statistics.json").parent.mkdir(parents=True, exist_ok=True)
        (out / "statistics.json").write_text(jsonio.dumps(st.to_json(), indent=1))
        acc = [m for m in ("e_t", "e_r", "e_s_sym", "e_s") if m in metrics][:3]
        seg = [m for m in ("e_start", "e_end", "e_rmse") if m in metrics]
        trajectory = [m for m in TRAJECTORY_STATS_METRICS if m in metrics]
        note = (
            f"{len(ok)} evaluated runs, {st.n_outliers} multivariate outliers removed (squared Mahalanobis "
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
                tables.write_all(table, tab_dir, name, caption)
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
            tables.write_all(td, tab_dir, f"table3_drift_{direction}", f"{what} medians, {direction} runs only")
            sections.append((f"{what}, {direction} runs only", tables.to_html(td)))
    else:
        sections.append(("Statistics", "<p>Fewer than two methods with evaluated runs: no group comparison.</p>"))

    res = tables.resources_table(df[df.status.isin(["done", "failed"])]) if "status" in df else pd.DataFrame()
    if not res.empty:
        tables.write_all(res, tab_dir, "table2_resources", "Mean resources per run")
        sections.append(("Resources (Table 2 layout)", tables.to_html(res)))
    # the campaign's accuracy figure per run: TUM-Mono's e_align, else ATE (datasets without TUM-Mono's metrics)
    main = next((m for m in ("e_align", "ate_rmse") if m in df.columns and df[m].notna().any()), None)
    if main is not None and "direction" in df.columns:
        mb = tables.motion_bias_table(df, main)
        tables.write_all(mb, tab_dir, "motion_bias", f"Forward vs backward {main}")
        sections.append(("Motion bias: forward vs backward", tables.to_html(mb)))
        repro = tables.reproduction_table(df[df.status == "done"] if "status" in df else df, main)
        if not repro.empty:
            tables.write_all(repro, tab_dir, "reproduction", f"Reproduction: new runs vs published, {main}")
            sections.append(("Reproduction: new runs vs published", tables.to_html(repro)))
        seq = tables.per_sequence_table(df, main)
        if not seq.empty:
            tables.write_all(seq, tab_dir, f"{main}_per_sequence", f"Median {main} per method and sequence")
            sections.append((f"Median {main} per sequence", tables.to_html(seq)))

    figs: list[Path] = []
    if not ok.empty:
        for m in ("e_t", "e_r", "e_s_sym", "e_start", "e_end", "ate_rmse", "rpe_t_rmse"):
            if m in metrics:
                figs.append(figures.cumulative(ok, m, fig_dir))
        if main is not None:
            figs.append(figures.cumulative(ok, main, fig_dir, f"cumulative_{main}_motion_bias", bold_all=True))
            figs.append(figures.heatmap(df, fig_dir, main))
    if st is not None:
        for m in metrics:
            figs.append(figures.boxplot(st, m, fig_dir))
    figs += _trajectory_figures(df, fig_dir, trajectory_sequences)

    index = out / "index.html"
    index.write_text(_html(results.name, sections, figs))
    return index


def _trajectory_figures(df: pd.DataFrame, folder: Path, n_sequences: int) -> list[Path]:
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
            out.append(figures.trajectories(runs, gt, full, folder, sequence, metric))
    return out


def _html(title: str, sections: list[tuple[str, str]], figs: list[Path]) -> str:
    parts = [f"<h2>{html.escape(h)}</h2>{body}" for h, body in sections]
    for f in figs:
        data = base64.b64encode(f.read_bytes()).decode()
        caption = html.escape(f.stem.replace("_", " "))
        label = LABELS.get(f.stem.split("_", 1)[-1], "")
        parts.append(
            f'<figure><img alt="{caption}" src="data:image/png;base64,{data}">'
            f"<figcaption>{caption}{(' - ' + html.escape(label)) if label else ''}</figcaption></figure>"
        )
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
        f"<style>{style}</style>{check}</head><body><h1>Campaign {html.escape(title)}</h1>"
        + "".join(parts)
        + "</body></html>"
    )
