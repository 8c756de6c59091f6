"""The report of a campaign: statistics, tables (CSV, Markdown, LaTeX), figures (PNG, SVG) and interactive
trajectory views, gathered in report/index.html; within each dataset (report/datasets/<name>/ when a campaign has
several). The page opens with the provenance of the results and links every file it shows; it works offline (its
one script library, plotly.js, is written beside it)."""

from __future__ import annotations

import fcntl
import re
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from slamrun.analysis import figures, interactive, page, tables
from slamrun.analysis.colours import method_colours
from slamrun.analysis.datasets import with_left_out
from slamrun.analysis.left_out import left_out, section_flags, shown_in
from slamrun.analysis.load import NO_DATASET, by_dataset, counted, evaluated, load_results, main_metric, metrics_for
from slamrun.analysis.paths import sequence_paths
from slamrun.analysis.provenance import provenance
from slamrun.analysis.published import beside, method_params
from slamrun.analysis.published import figures as published_figures
from slamrun.analysis.robustness import (
    AREA_BOUND,
    BREAKDOWN_PCT,
    baseline,
    breakdown_table,
    kinds,
    level_statistics,
    long_table,
    paired_table,
    perturbed,
    success_rates,
    summary_table,
)
from slamrun.analysis.stats import screen, study_statistics
from slamrun.analysis.summary import method_summary, pooled_summary, ranked_by, sequence_ranks
from slamrun.core import jsonio
from slamrun.engine.folders import REPORT, claim_output_folder
from slamrun.results.catalogue import (
    ATE,
    CPU_WAIT_PCT,
    FIGURE_METRICS,
    KITTI,
    LABELS,
    MAIN_METRICS,
    METRIC_TITLES,
    PROGRESS_METRICS,
    RPE,
    TRAJECTORY_STATS_METRICS,
    columns_of,
    metric_of,
)
from slamrun.results.files import CampaignFiles
from slamrun.results.marks import marked
from slamrun.results.vocabulary import METHOD_FAILURES, UNDER_MIN_COVERAGE

RUNS_COLUMNS = {
    "runs": "runs",
    "done": "done",
    "failed": "failed (method)",
    "infra": "infra",
    "contended": "of which contended",
    "pending": "pending",
    "success_pct": "success %",
    "failure_pct": "failure %",
    "evaluated": "evaluated",
    "not_evaluable": "not evaluable",
}
RUNS_CAPTION = (
    "Counts of runs per method; success and failure rates over the method's results (infrastructure failures, "
    "contended runs among them, and unfinished runs left out); then each kind of the method's failures."
)


CONTENDED_CAPTION = (
    "Runs with an attempt lost while its threads waited for a CPU beyond the spec's contention_pct (the machine's "
    "load): that attempt was not charged to the method and the run was tried again; 'ended' is how it finally ended "
    "(contended: every attempt was, it is retried at the next start)."
)


def runs_table(df: pd.DataFrame) -> pd.DataFrame:
    """The report's runs-and-failures table: the per-method summary's counts and rates (rates over the
    method's results: infrastructure failures and unfinished runs are left out), and each failure kind."""
    s = method_summary(df)
    if s.empty:
        return s
    out = s[["method", *RUNS_COLUMNS, *METHOD_FAILURES]].rename(columns=RUNS_COLUMNS)
    return out.round({"success %": 1, "failure %": 1})


@dataclass
class Section:
    """A part of the page: its heading, its content (HTML) and the parts under it."""

    title: str
    html: str = ""
    parts: list[Section] = field(default_factory=list)


def write_report(
    results: Path, level: float = 0.999, adjust: str = "holm", alpha: float = 0.05, trajectory_sequences: int = 2
) -> Path:
    """report/index.html with its tables, figures and views. Every statistic, table and figure is of one dataset: a
    campaign of several datasets gets one section (and folder report/datasets/<name>/) per dataset, after the views
    that are sound to pool (counts, success rates, ranks within sequences), labelled as pooled."""
    results = Path(results)
    df = load_results(results)  # first: results that cannot be read leave no report folder behind
    out = results / "report"
    claim_output_folder(out, REPORT)  # its marker is also the lock below
    with one_at_a_time(out / REPORT.marker):
        return _write_report(df, results, out, level, adjust, alpha, trajectory_sequences)


@contextmanager
def one_at_a_time(marker: Path) -> Iterator[None]:
    """An exclusive lock on the report folder's marker while a report is written: two reports of one campaign at
    once (a user's and the campaign's end) are written one after the other, never one clearing the other's files."""
    with open(marker, "a") as fh:  # "a": the marker's content stays
        fcntl.flock(fh, fcntl.LOCK_EX)
        yield


def _write_report(
    df: pd.DataFrame, results: Path, out: Path, level: float, adjust: str, alpha: float, trajectory_sequences: int
) -> Path:
    """Every table, figure and statistic of the study is of the runs on ordinary views (the baseline); the runs on
    perturbed views are in each dataset's Robustness section alone."""
    clear_previous(out)
    out.mkdir(parents=True, exist_ok=True)
    everything = by_dataset(df)
    groups = {name: baseline(part) for name, part in everything.items()}
    options = {"level": level, "adjust": adjust, "alpha": alpha, "trajectory_sequences": trajectory_sequences}
    options["colours"] = method_colours(df.method) if "method" in df.columns else None
    prov = provenance(results, df)
    options |= {"measurement": prov.measurement, "contention_pct": prov.contention_pct}
    published, unread = published_figures(prov.published)
    params = method_params(results)
    prov.notes += [f"published figures left out: {why}" for why in unread]
    stats_options = {k: options[k] for k in ("level", "adjust", "alpha", "colours")}
    sections = [Section("Provenance", page.provenance_html(prov, out, results))]
    if len(groups) == 1:
        name, part = next(iter(groups.items()))
        label = name if name != NO_DATASET else ""
        body = dataset_report(part, out, out, label, **options)
        body += published_section(part, published, params, out, out, label)
        body += robustness_report(everything[name], out, out, label, **stats_options)
        intro = Section(f"Dataset {name}" if label else "Results", "", body)
        sections.append(intro)
    else:
        sections.append(Section("All datasets (pooled)", "", pooled_report(baseline(df), out)))
        for name, folder in _folders(groups).items():
            body = dataset_report(groups[name], out / "datasets" / folder, out, name, **options)
            body += published_section(groups[name], published, params, out / "datasets" / folder, out, name)
            body += robustness_report(everything[name], out / "datasets" / folder, out, name, **stats_options)
            sections.append(Section(f"Dataset {name}", "", body))
    robust = robustness_csv(everything)
    if not robust.empty:
        robust.to_csv(CampaignFiles(results).robustness_csv, index=False)
    views = any(page.has_view(s.html) for s in _walk(sections))
    if views:
        interactive.write_library(out)
    index = out / "index.html"
    index.write_text(page.document(f"Campaign {prov.campaign}", sections, views))
    return index


GENERATED = {"tables": (".csv", ".md", ".tex"), "figures": (".png", ".svg"), "views": (".js",)}


def clear_previous(out: Path) -> None:
    """Remove what an earlier report wrote into `out` (its tables, figures, views, statistics and plotly.js, also
    those of datasets no longer in the results), so that no file of another content or name stays beside the new
    ones; files of other kinds are left alone."""
    levels = [out, *((out / "datasets").iterdir() if (out / "datasets").is_dir() else [])]
    for level in levels:
        if not level.is_dir() or level.is_symlink():
            continue
        for sub, suffixes in GENERATED.items():
            folder = level / sub
            if folder.is_dir() and not folder.is_symlink():
                for f in folder.iterdir():
                    if f.suffix in suffixes and (f.is_symlink() or f.is_file()):
                        f.unlink()
                _remove_if_empty(folder)
        for f in level.glob("statistics*.json"):
            if f.is_symlink() or f.is_file():
                f.unlink()
        if level != out:
            _remove_if_empty(level)
    library = out / interactive.PLOTLY_JS
    if library.is_symlink() or library.is_file():
        library.unlink()  # written again where the new report has a view


def _remove_if_empty(folder: Path) -> None:
    if not any(folder.iterdir()):
        folder.rmdir()


def _walk(sections: list[Section]):
    for s in sections:
        yield s
        yield from _walk(s.parts)


def pooled_report(df: pd.DataFrame, out: Path) -> list[Section]:
    """The sections of a campaign of several datasets that pool them, where pooling is sound: the runs and
    failures per method (counts and rates) and the mean rank of each method within the sequences."""
    tab_dir = out / "tables"
    fails = runs_table(df)
    title = "Runs and failures per method, all datasets (pooled)"
    marks = section_flags(df)  # a method marked in any dataset is marked here
    sections = [Section(title, page.table(fails, tab_dir, out, "failures", title, RUNS_CAPTION, marks=marks))]
    ranks = pooled_summary(df)[["method", "mean_rank", "sequences_ranked"]]
    ranks = ranks.rename(columns={"mean_rank": "mean rank", "sequences_ranked": "sequences"}).round({"mean rank": 2})
    by = ", ".join(f"{d}: {m}" for d, m in ranked_by(df).items())
    title = "Mean rank within sequences, all datasets (pooled)"
    note = (
        f"Each sequence ranks its methods by their median ({by}; 1 best, ties share the mean rank; a method with "
        "results but no evaluated run shares the last rank); a method's mean rank is over the sequences it ran. "
        "Every other table and figure of this report is within one dataset: values in metres of different datasets "
        "are not one population."
    )
    html = page.table(ranks, tab_dir, out, "pooled_ranks", f"{title}; ranked by {by}", note, marks=marks)
    seq = sequence_ranks(df)
    title_seq = "Each method's rank within each sequence"
    html += page.table(seq, tab_dir, out, "sequence_ranks", title_seq, "", show=False, marks=marks)
    sections.append(Section(title, html))
    return sections


def trajectory_title(metrics: list[str]) -> str:
    """What a table of ATE, RPE and KITTI's figures holds, by the metrics it has: "ATE and RPE", ..."""
    names = [METRIC_TITLES[m] for m in (ATE, RPE, KITTI) if any(metric_of(c) == m for c in metrics)]
    if len(names) < 2:
        return "".join(names) or "Trajectory metrics"
    return ", ".join(names[:-1]) + " and " + names[-1]


def dataset_report(
    df: pd.DataFrame,
    out: Path,
    root: Path,
    dataset: str = "",
    level: float = 0.999,
    adjust: str = "holm",
    alpha: float = 0.05,
    trajectory_sequences: int = 2,
    colours: dict[str, str] | None = None,
    measurement: str = "",
    contention_pct: float | None = None,
) -> list[Section]:
    """The study's report of one dataset's runs into `out` (statistics*.json, tables/, figures/, views/): its
    sections, their links relative to `root` (the folder of index.html). `dataset` labels captions and titles."""
    fig_dir, tab_dir = out / "figures", out / "tables"
    where = f" ({dataset})" if dataset else ""
    metrics = metrics_for(df)
    df, excluded = screen(df, metrics)  # figures that are no measurement: left out of every view, named
    ok = evaluated(df, metrics)
    sections = []
    marks = section_flags(df)  # low coverage, diverged: marked in every table and figure below
    names = {m: marked(m, marks) for m in marks}

    fails = runs_table(df)
    title = "Runs and failures per method"
    html_fails = page.table(fails, tab_dir, root, "failures", title + where, RUNS_CAPTION, marks=marks)
    notes = [coverage_note(df), *missing_metric_notes(df)]
    sections.append(Section(title, html_fails + "".join(f"<p>{page.esc(n)}</p>" for n in notes)))

    st = None
    if ok.method.nunique() >= 2:
        st = study_statistics(ok, metrics, level=level, adjust=adjust, alpha=alpha)
        st.excluded = excluded
        st = with_left_out(st, df)
        out.mkdir(parents=True, exist_ok=True)
        (out / "statistics.json").write_text(jsonio.dumps(st.to_json(), indent=1))
        sections.append(_statistics(st, df, metrics, out, root, where, level, adjust, alpha))
    else:
        none = "<p>Fewer than two methods with evaluated runs: no group comparison.</p>"
        sections.append(Section("Statistics", none + page.note_lines([left_out(df, ok.method.unique(), metrics)])))

    sections += _resources(df, tab_dir, root, where, measurement, contention_pct)
    # the campaign's accuracy figure per run: TUM-Mono's e_align, else ATE (datasets without TUM-Mono's metrics)
    main = main_metric(df)
    if main is not None and "direction" in df.columns:
        sections += _per_run_tables(df, main, tab_dir, root, where)

    figs = []  # (figure, its metric)
    if not ok.empty:
        for m in FIGURE_METRICS:
            if m in metrics:
                figs.append((figures.cumulative(ok, m, fig_dir, label=dataset, colours=colours, names=names), m))
        if main is not None:
            name = f"cumulative_{main}_motion_bias"
            figs.append((figures.cumulative(ok, main, fig_dir, name, True, dataset, colours, names), main))
            figs.append((figures.heatmap(df, fig_dir, main, label=dataset, names=names), None))
    if st is not None:
        for m in metrics:
            figs.append((figures.boxplot(st, m, fig_dir, dataset, adjust, alpha, names), m))
    if figs:
        html = ""
        for f, m in figs:
            if m is None:  # the heat map: every run of every method
                shown, notes = set(marks), ()
            elif st is not None and f.stem.startswith("box_"):
                shown = set(st.metrics[m].medians)
                notes = (left_out(df, shown, [m]),)
            else:
                shown = set(counted(ok, m).method.astype(str))
                notes = (left_out(df, shown, [m]),)
            html += page.figure(f, root, _caption(f, dataset), (*notes, *page.mark_notes(marks, shown)))
        sections.append(Section("Figures", html))
    traj = _trajectories(df, out, root, trajectory_sequences, dataset, names)
    if traj is not None:
        sections.append(traj)
    return sections


ROBUSTNESS_INTRO = (
    "Each sequence was also played with its frames made worse (README, Robustness), every level a prepared view of "
    "its own, forward and backward as the baseline; the baseline (level none) is the ordinary view, the runs every "
    "other table of this report is made of. Each run on a perturbed view is paired with the same method's run of "
    "the same sequence, direction and trial on the baseline: the ratio of their figures says how much worse the "
    "method got, a failure of its own counts as a ratio at infinity (never dropped), and the area under the "
    f"cumulative curve of the ratios from 1 to {AREA_BOUND:g} (log scale) sums a level up: 1 unharmed, 0 failed or "
    f"{AREA_BOUND:g} times worse on every pair. Success rates are over the method's results (infrastructure "
    "failures and unfinished runs left out). The figures' medians and quartiles are of evaluated runs only: read them "
    "beside the success rate and the paired figures, for a method that fails the hard runs keeps a good median."
)


def robustness_report(
    df: pd.DataFrame,
    out: Path,
    root: Path,
    dataset: str = "",
    level: float = 0.999,
    adjust: str = "holm",
    alpha: float = 0.05,
    colours: dict[str, str] | None = None,
) -> list[Section]:
    """The Robustness section of one dataset's runs (all of them, perturbed and baseline), or none where no run
    was on a perturbed view: success rates per level, the level at which each method breaks down, one figure
    per kind (each metric and the success rate against the level), and the statistics within each level."""
    if not perturbed(df):
        return []
    fig_dir, tab_dir = out / "figures", out / "tables"
    where = f" ({dataset})" if dataset else ""
    metrics = metrics_for(df)
    rates = success_rates(df)
    parts = [Section("Robustness", f"<p>{page.esc(ROBUSTNESS_INTRO)}</p>")]
    metric = main_metric(df)
    if metric is not None:
        parts += _paired_sections(df, metric, tab_dir, root, where)
    title = f"Level at which the success rate falls under {BREAKDOWN_PCT:g} %"
    caption = (
        "Per method and perturbation, the mildest level whose success rate is under "
        f"{BREAKDOWN_PCT:g} %: never (every level tested stayed at or above it), baseline (already under it on the "
        "ordinary view)."
    )
    html = page.table(breakdown_table(rates), tab_dir, root, "robustness_breakdown", title + where, caption)
    parts.append(Section(title, html))
    title = "Success rate per perturbation level"
    caption = "Runs, the method's results (done or failed by it), done, and the success rate, per level."
    parts.append(Section(title, page.table(rates, tab_dir, root, "robustness_success", title + where, caption)))
    contended = tables.contended_runs_table(df[df["perturbation"] != "none"])
    if not contended.empty:
        title = "Runs on perturbed views with a contended attempt"
        html = page.table(contended, tab_dir, root, "robustness_contended_runs", title + where, CONTENDED_CAPTION)
        parts.append(Section(title, html))
    figs = [figures.robustness(df, k, metrics, fig_dir, label=dataset, colours=colours) for k in kinds(df)]
    caption = (
        "Per level: the success rate; paired against each method's own baseline, the area and the median ratio "
        "(x on the top edge: half or more of the pairs failed); then the median (line) and first to third quartile "
        "(band) of the evaluated runs alone."
    )
    html = "".join(page.figure(f, root, caption) for f in figs)
    curves = [figures.robustness_curves(df, k, fig_dir, label=dataset, colours=colours) for k in kinds(df)]
    caption = (
        f"Per level, each method's share of pairs whose figure is at most x times its baseline's, x from 1 to "
        f"{AREA_BOUND:g}: a failure is never reached, so the curve ends under 1 by the share failed; the area under "
        "the curve over the axis' width is the paired table's area."
    )
    html += "".join(page.figure(f, root, caption) for f in curves if f is not None)
    parts.append(Section("Robustness figures", html))
    table, full = level_statistics(df, metrics, level=level, adjust=adjust, alpha=alpha)
    if not table.empty:
        out.mkdir(parents=True, exist_ok=True)
        (out / "statistics_robustness.json").write_text(jsonio.dumps(full, indent=1))
        title = "Statistics within each perturbation level"
        caption = (
            "The study's procedure on each level's evaluated runs alone (as within a dataset): runs counted, medians "
            f"and letter groups (methods sharing a letter do not differ at alpha {alpha:g}, {adjust}-adjusted), and "
            "the Kruskal-Wallis rows; the full tests in statistics_robustness.json."
        )
        parts.append(Section(title, page.table(table, tab_dir, root, "robustness_statistics", title + where, caption)))
    else:
        none = "<p>No level has two methods with evaluated runs: no group comparison.</p>"
        parts.append(Section("Statistics within each perturbation level", none))
    return [Section("Robustness", parts[0].html, parts[1:])]


PUBLISHED_CAPTION = (
    "Each method's median over its evaluated runs of a sequence beside the figure its authors published for it (the "
    "same method, sequence and metric), with how it was published and where the protocols differ; published "
    "figures are only shown, never tested against this campaign's runs (README, Published figures)."
)


def published_section(
    df: pd.DataFrame, published, params: dict[str, dict], out: Path, root: Path, dataset: str = ""
) -> list[Section]:
    """The published figures matching this dataset's runs (and their methods' `params`, by label), beside the
    campaign's medians; none where none match."""
    table = beside(df, published, params)
    if table.empty:
        return []
    title = "Published figures beside this campaign's"
    where = f" ({dataset})" if dataset else ""
    html = page.table(table, out / "tables", root, "published", title + where, PUBLISHED_CAPTION)
    return [Section(title, html)]


def _paired_sections(df: pd.DataFrame, metric: str, tab_dir: Path, root: Path, where: str) -> list[Section]:
    """The summary across kinds (area and breakdown per kind and method) and the paired figures per level."""
    name = LABELS.get(metric, metric)
    title = "Robustness summary: area and breakdown level per perturbation"
    caption = (
        f"Per method and perturbation kind: the area of its paired {name} ratios (the mean of its levels' areas; "
        f"1 unharmed, 0 failed or {AREA_BOUND:g} times worse on every pair) and the mildest level whose success rate "
        f"is under {BREAKDOWN_PCT:g} % (never: at no level tested; baseline: already on the ordinary view)."
    )
    html = page.table(summary_table(df, metric).round(3), tab_dir, root, "robustness_summary", title + where, caption)
    sections = [Section(title, html)]
    title = f"Paired against each method's own baseline ({name})"
    caption = (
        "Per perturbation level and method: pairs (a run on the perturbed view with a result, and its baseline run "
        "of the same sequence, direction and trial with a figure), how many the method failed (ratio at infinity), "
        "runs whose baseline run has no figure (no pair), the median ratio of the perturbed figure to the baseline's "
        "over all pairs (failed where half or more failed: failures count at infinity) and the area."
    )
    shown = paired_table(df, metric).round({"median ratio": 3, "area": 3})
    shown["median ratio"] = [("failed" if v == float("inf") else v) for v in shown["median ratio"]]
    sections.append(Section(title, page.table(shown, tab_dir, root, "robustness_paired", title + where, caption)))
    return sections


def robustness_csv(everything: dict[str, pd.DataFrame]) -> pd.DataFrame:
    """results/robustness.csv: every dataset's long robustness table (long_table), on its main metric."""
    parts = []
    for name, part in everything.items():
        metric = main_metric(part)
        if perturbed(part) and metric is not None:
            parts.append(long_table(part, metric, name if name != NO_DATASET else ""))
    return pd.concat(parts, ignore_index=True) if parts else pd.DataFrame()


def _resources(
    df: pd.DataFrame, tab_dir: Path, root: Path, where: str, measurement: str, contention_pct: float | None
) -> list[Section]:
    """The resources table (Table 2's layout) and the runs with a contended attempt, where there are any."""
    sections = []
    finished = df[df.status.isin(["done", "failed"])] if "status" in df else pd.DataFrame()
    res = tables.resources_table(finished, contention_pct) if not finished.empty else pd.DataFrame()
    if not res.empty:
        title = "Resources: means per run (Table 2 layout)"
        caption = "Means over each method's finished runs (done or failed) of the resources the runner measured"
        caption += f", taken under measurement {measurement}." if measurement else "."
        if contention_pct is not None and CPU_WAIT_PCT in finished.columns:
            caption += (
                f" Runs whose threads waited for a CPU more than {contention_pct:g} % of their wall time beyond the "
                "wait they cause themselves (cpu_wait_own_pct: a method with more busy threads than its CPUs) had "
                "their FPS and CPU figures taken under contention: counted per method."
            )
        extra = tuple(tables.more_threads_than_declared(finished))
        html = page.table(res, tab_dir, root, "table2_resources", title + where, caption, notes=extra)
        sections.append(Section(title, html))
    contended = tables.contended_runs_table(df)
    if not contended.empty:
        title = "Runs with a contended attempt"
        html = page.table(contended, tab_dir, root, "contended_runs", title + where, CONTENDED_CAPTION)
        sections.append(Section(title, html))
    return sections


def missing_metric_notes(df: pd.DataFrame) -> list[str]:
    """For each metric the dataset asked for that no run has a value of (its runs' messages say why), one line
    with the reason: a column a report leaves out is never left out without a word."""
    if "message" not in df.columns or "status" not in df.columns:
        return []
    done = df[df.status == "done"]
    out = []
    for name in (ATE, RPE, KITTI):
        column, title = next(c for c in columns_of(name) if c in PROGRESS_METRICS), METRIC_TITLES[name]
        if column in df.columns and df[column].notna().any():
            continue
        reasons = done["message"].dropna().astype(str)
        reasons = reasons[reasons.str.contains(f"{name}: ", regex=False)]
        if reasons.empty:
            continue
        why = reasons.iloc[0].split(f"{name}: ", 1)[1].split("; ")[0]
        out.append(f"{title}: no value in this dataset's {len(done)} done run(s), so no column or figure of it: {why}.")
    return out


def coverage_note(df: pd.DataFrame) -> str:
    """What the dataset's coverage threshold did, in one sentence: the runs lost under `min_coverage`, or that there
    was none (coverage then stands beside every figure)."""
    messages = df["message"].fillna("").astype(str) if "message" in df.columns else pd.Series(dtype=str)
    under = messages[messages.str.contains(UNDER_MIN_COVERAGE, regex=False)]
    if under.empty:
        return (
            "No coverage threshold (min_coverage) excluded a run: every done run's figures are tested, and each "
            "table and box plot gives the methods' median coverage (the share of the frames each was given with a "
            "pose)."
        )
    least = sorted({m.rsplit(" ", 1)[-1] for m in under})
    return (
        f"{len(under)} run(s) gave poses for fewer than min_coverage {', '.join(least)} of the sequence's frames: "
        "counted as lost (a tracking failure), their figures left out of the statistics."
    )


def _statistics(st, df, metrics, out, root, where, level, adjust, alpha) -> Section:
    """The statistics' sections: what was done, the medians with letters, every test with its p-value, the
    pairwise tests, and the same per direction; under each, the methods of the dataset (`df`, its runs) it leaves
    out and why."""
    tab_dir = out / "tables"
    ok = evaluated(df, metrics)
    acc = [m for m in ("e_t", "e_r", "e_s_sym", "e_s") if m in metrics][:3]
    seg = [m for m in ("e_start", "e_end", "e_rmse") if m in metrics]
    trajectory = [m for m in TRAJECTORY_STATS_METRICS if m in metrics]
    counting = f" Of these, {st.counting_note()}." if st.counting_note() else ""
    note = (
        f"{len(ok)} evaluated runs{where}, each metric tested on every run with a figure of it (a run without one "
        f"metric stays in the others'); {st.outlier_text()} (chi-square {level} quantile).{counting} "
        f"Letters: pairwise Wilcoxon rank-sum tests, {adjust} adjustment, alpha {alpha}; methods that share a letter "
        "do not differ significantly."
    )
    tested = {m: set(s.medians) for m, s in st.metrics.items()}
    marks = section_flags(df)
    html = f"<p>{page.esc(note)}</p>" + page.note_lines(st.excluded_lines())
    html += page.links({"statistics (JSON)": out / "statistics.json"}, root)
    parts = []
    what = (
        "Per method: the runs counted (outliers removed, copies once), their median coverage (share of the frames "
        "the method was given with a pose), and per metric the median over those runs and its letter groups (LaTeX: "
        "superscripts; the best median in bold). Last rows: Kruskal-Wallis chi-square, its degrees of freedom and "
        "p-value."
    )
    for chosen, name, title in (
        (acc, "table3_drift", "Drift: medians with letter groups (Table 3 layout)"),
        (seg, "table4_segments", "Segment alignment errors: medians with letter groups (Table 4 layout)"),
        (trajectory, "trajectory_metrics", f"{trajectory_title(trajectory)}: medians with letter groups"),
    ):
        if chosen:
            table = tables.medians_with_letters(st, chosen)
            gaps = (left_out(df, shown_in(table, chosen), chosen),)
            html_table = page.table(
                table, tab_dir, root, name, title + where, what, tuple(chosen), notes=gaps, marks=marks
            )
            parts.append(Section(title, html_table))
    title = "Tests of each metric"
    caption = (
        "Kruskal-Wallis rank-sum test across the methods (chi-square, df, p); Levene's test of equal variances "
        "(median-centred: F, p); Lilliefors' normality test per method (p; none under five runs or without spread)."
    )
    gaps = (left_out(df, tested, metrics),)
    html_tests = page.table(tables.tests_table(st), tab_dir, root, "tests", title + where, caption, notes=gaps)
    parts.append(Section(title, html_tests))
    title = "Pairwise Wilcoxon rank-sum tests"
    caption = f"Each pair of methods: p adjusted ({adjust}) and unadjusted; different when the adjusted p < {alpha}."
    pairs = tables.pairwise_table(st, adjust, alpha)
    parts.append(Section(title, page.table(pairs, tab_dir, root, "pairwise", title + where, caption, notes=gaps)))
    # the same procedure per direction: motion bias can change the ranking
    chosen, name = (acc, "table3_drift") if acc else (trajectory, "trajectory_metrics")
    what_dir = "Drift" if acc else trajectory_title(trajectory)
    skipped = []
    for direction in ("forward", "backward"):
        part = ok[ok.direction == direction] if "direction" in ok.columns else ok.iloc[0:0]
        if not chosen or part.method.nunique() < 2:
            why = "fewer than two methods with evaluated runs" if chosen else "no metric"
            skipped.append(f"{direction} runs only: {why}")
            continue
        sd = with_left_out(study_statistics(part, metrics, level=level, adjust=adjust, alpha=alpha), df)
        (out / f"statistics_{direction}.json").write_text(jsonio.dumps(sd.to_json(), indent=1))
        td = tables.medians_with_letters(sd, chosen)
        title = f"{what_dir}: medians with letter groups, {direction} runs only"
        gaps = (left_out(df[df.direction == direction], shown_in(td, chosen), chosen),)
        html_dir = page.table(
            td, tab_dir, root, f"{name}_{direction}", title + where, what, tuple(chosen), notes=gaps, marks=marks
        )
        html_dir += page.links({f"statistics, {direction} runs (JSON)": out / f"statistics_{direction}.json"}, root)
        parts.append(Section(title, html_dir))
    if skipped:
        text = "".join(f"<li>{page.esc(s)}</li>" for s in skipped)
        parts.append(Section("Statistics per direction left out", f"<ul>{text}</ul>"))
    return Section("Statistics", html, parts)


def _per_run_tables(df: pd.DataFrame, main: str, tab_dir: Path, root: Path, where: str) -> list[Section]:
    """Motion bias, reproduction and per-sequence tables of the accuracy figure `main`."""
    label = LABELS.get(main, main)
    out = []
    marks = section_flags(df)
    mb = tables.motion_bias_table(df, main)
    title = f"Motion bias: forward vs backward {main}"
    caption = (
        f"Per method, the number of evaluated runs per direction (copies of a run once), the median {label} of each "
        "direction, and the p-value of a Wilcoxon rank-sum test between the directions."
    )
    gaps = (left_out(df, set(mb.method.astype(str)) if not mb.empty else set(), [main]),)
    full = f"Forward vs backward {main}{where}"
    out.append(Section(title, page.table(mb, tab_dir, root, "motion_bias", full, caption, notes=gaps, marks=marks)))
    repro = tables.reproduction_table(df[df.status == "done"] if "status" in df else df, main)
    if not repro.empty:
        title = "Reproduction: new runs vs published"
        caption = (
            f"Imported runs (SOURCE:method) beside the campaign's own runs of that method: the median {label} of "
            "each, how many runs, and the p-value of a Wilcoxon rank-sum test between them."
        )
        full = f"Reproduction: new runs vs published, {main}{where}"
        out.append(Section(title, page.table(repro, tab_dir, root, "reproduction", full, caption)))
    seq = tables.per_sequence_table(df, main)
    if not seq.empty:
        title = f"Median {main} per sequence"
        caption = f"The median {label} of each method's evaluated runs on each sequence (rows: methods; copies once)."
        full = f"Median {main} per method and sequence{where}"
        gaps = (left_out(df, set(seq.method.astype(str)), [main]),)
        html = page.table(seq, tab_dir, root, f"{main}_per_sequence", full, caption, notes=gaps, marks=marks)
        out.append(Section(title, html))
    return out


def _caption(f: Path, dataset: str) -> str:
    stem = f.stem
    kind, _, rest = stem.partition("_")
    what = {
        "cumulative": "cumulative distribution",
        "box": "box plots with letter groups",
        "heatmap": "every run's value (heat map)",
    }.get(kind, kind)
    metric = rest.removesuffix("_motion_bias")
    text = f"{what} of {LABELS.get(metric, metric)}"
    if stem.endswith("_motion_bias"):
        text += ", forward and backward runs apart"
    return (f"{dataset}: " if dataset else "") + text


def _trajectories(
    df: pd.DataFrame, out: Path, root: Path, n_static: int, dataset: str, names: dict[str, str] | None = None
) -> Section | None:
    """Per sequence, an interactive 3D view of each method's best, median and worst run over the ground truth
    (by ATE where the campaign has it, else e_align); a static top view (PNG, SVG) of the first `n_static`."""
    metric = next((m for m in MAIN_METRICS[::-1] if m in df.columns and df[m].notna().any()), None)
    if "run_dir" not in df.columns or metric is None:
        return None
    parts = []
    files = _folders({str(s): None for s in sorted(df.sequence.dropna().astype(str).unique())})
    opened = False
    for sequence, file in files.items():
        paths = sequence_paths(df, sequence, metric)
        if paths is None:
            continue
        html = ""
        if len(parts) < n_static:
            png = figures.trajectories(paths, out / "figures", label=dataset, names=names)
            html += page.figure(png, root, (f"{dataset}: " if dataset else "") + f"{sequence}, top view")
        element = "view-" + re.sub(r"[^A-Za-z0-9_-]", "_", f"{out.relative_to(root).as_posix()}-{file}")
        script = interactive.write_view(
            paths, out / "views" / f"{file}.js", element, f"{sequence}: {paths.aligned_by()}", names
        )
        html += page.view(script, root, element, sequence, paths, open_=not opened)
        opened = True
        parts.append(Section(sequence, html))
    if not parts:
        return None
    note = (
        f"Each method's best, median and worst evaluated run by {metric} over the ground truth, aligned as the "
        "metric aligns them. The views are interactive: drag to rotate, scroll to zoom, click a legend entry to "
        "hide or show a run (double-click to show it alone)."
    )
    marks = page.note_lines(page.mark_notes(section_flags(df), df.method.astype(str).unique()))
    return Section("Trajectories", f"<p>{page.esc(note)}</p>{marks}", parts)


def _folders(groups: dict) -> dict[str, str]:
    """A folder (or file) name per name: its letters, digits, '.', '-' and '_' (others '_'), unique."""
    out: dict[str, str] = {}
    for name in groups:
        base = re.sub(r"[^A-Za-z0-9._-]", "_", name).strip(".") or "dataset"
        folder, k = base, 2
        while folder in out.values():
            folder, k = f"{base}_{k}", k + 1
        out[name] = folder
    return out
