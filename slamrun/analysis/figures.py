"""The study's figures from DataFrames (matplotlib, headless): PNG and SVG files, fit for a paper: no text over
another, every value axis with at least three labelled ticks, every axis labelled with its unit."""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import matplotlib.ticker  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from matplotlib.colors import ListedColormap, LogNorm, Normalize  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Patch, Rectangle  # noqa: E402

from slamrun.analysis.colours import method_colours  # noqa: E402
from slamrun.analysis.load import counted  # noqa: E402
from slamrun.analysis.paths import SequencePaths  # noqa: E402
from slamrun.analysis.stats import StudyStats  # noqa: E402
from slamrun.core.ticks import log_steps  # noqa: E402
from slamrun.results.catalogue import LABELS, MAIN_METRICS  # noqa: E402
from slamrun.results.vocabulary import INFRA_FAILURES  # noqa: E402

MAIN = MAIN_METRICS[0]  # TUM-Mono's e_align: the figures' metric when none is named

# best, median and worst run: told apart by colour and by line style (colour-blind safe, also in grey print)
PICK_STYLES = {"best": ("#1b9e77", "-", 1.6), "median": ("#7570b3", "--", 1.3), "worst": ("#d95f02", ":", 1.6)}


# horizontal boxes: `orientation` since matplotlib 3.10, `vert` before
HORIZONTAL = (
    {"orientation": "horizontal"}
    if tuple(int(x) for x in matplotlib.__version__.split(".")[:2]) >= (3, 10)
    else {"vert": False}
)


def save(fig, folder: Path, name: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    fig.savefig(folder / f"{name}.png", dpi=110, bbox_inches="tight")
    if fig.get_layout_engine() is not None:
        fig.set_layout_engine("none")  # laid out for the PNG: the SVG keeps that layout, not computed again
    fig.savefig(folder / f"{name}.svg", bbox_inches="tight")
    plt.close(fig)
    return folder / f"{name}.png"


def _labelled(label: str, title: str) -> str:
    """A figure's title headed by its dataset, where it has one."""
    return f"{label}: {title}" if label else title


def _number(x: float, _pos=None) -> str:
    """A tick's value as a reader writes it: 0.2, 5, 1e-05."""
    return f"{x:g}"


def use_log_scale(values: np.ndarray) -> bool:
    """Whether positive values span a decade or more (a log axis then reads better than a linear one)."""
    v = np.asarray(values, float)
    v = v[np.isfinite(v) & (v > 0)]
    return len(v) > 1 and v.max() / v.min() >= 10


def readable_log_ticks(axis, lo: float, hi: float) -> None:
    """Ticks of a log axis from lo to hi that a reader can read values off (slamrun.core.ticks: the live page's
    rule), each labelled with its whole value."""
    axis.set_major_locator(matplotlib.ticker.LogLocator(base=10, subs=log_steps(lo, hi), numticks=40))
    axis.set_major_formatter(matplotlib.ticker.FuncFormatter(_number))
    axis.set_minor_locator(matplotlib.ticker.LogLocator(base=10, subs=np.arange(1, 10), numticks=40))
    axis.set_minor_formatter(matplotlib.ticker.NullFormatter())


def cumulative(
    df: pd.DataFrame,
    metric: str,
    folder: Path,
    name: str | None = None,
    bold_all: bool = False,
    label: str = "",
    colours: dict[str, str] | None = None,
    names: dict[str, str] | None = None,
) -> Path:
    """The cumulative figure of `metric` (cumulative_figure), saved in `folder`."""
    figure = cumulative_figure(df, metric, bold_all, label, colours, names)
    return save(figure, folder, name or f"cumulative_{metric}")


def cumulative_figure(
    df: pd.DataFrame,
    metric: str,
    bold_all: bool = False,
    label: str = "",
    colours: dict[str, str] | None = None,
    names: dict[str, str] | None = None,
) -> plt.Figure:
    """Runs (y, whole numbers) whose error is below x, one curve per method, over the runs `counted` (done, with a
    figure, copies of a run once: a deterministic method's identical trials are one run), each method's n in its
    legend entry: best methods reach the top left; x is logarithmic where the values span a decade or more, else
    linear; `label` (the dataset) heads the title; the legend beside the axes, never over a curve; `colours`: the
    campaign's (method_colours), else these methods'; `names`: a method's name as shown (with its marks)."""
    fig, ax = plt.subplots(figsize=(7.4, 4.2), layout="constrained")
    df = counted(df, metric)
    names = names or {}
    methods = sorted(df.method.unique())
    colors = {**method_colours(methods), **(colours or {})}
    log = use_log_scale(df[metric].to_numpy(float))
    for m in methods:
        g = df[df.method == m]
        if bold_all and "direction" in g:
            for direction, style in (("forward", ":"), ("backward", "--")):
                v = _sorted(g.loc[g.direction == direction, metric], log)
                if len(v):
                    ax.step(v, np.arange(1, len(v) + 1), where="post", ls=style, lw=1, color=colors[m])
        v = _sorted(g[metric], log)
        if len(v):
            lw = 2.2 if bold_all else 1.6
            shown = f"{names.get(m, m)} (n={len(v)})"
            ax.step(v, np.arange(1, len(v) + 1), where="post", lw=lw, color=colors[m], label=shown)
    if log:
        v = df[metric].to_numpy(float)
        v = v[np.isfinite(v) & (v > 0)]
        ax.set_xscale("log")
        readable_log_ticks(ax.xaxis, v.min(), v.max())
    ax.set_xlabel(LABELS.get(metric, metric) + (" (log scale)" if log else ""))
    ax.set_ylabel("runs with a smaller error (copies once)")
    ax.yaxis.set_major_locator(matplotlib.ticker.MaxNLocator(integer=True))  # counts: 1, 2, 3, never 1.5
    ax.set_title(_labelled(label, f"cumulative {LABELS.get(metric, metric)}"), fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    handles, labels = ax.get_legend_handles_labels()
    if bold_all:  # the line styles, as drawn
        for style, lw, what in (("-", 2.2, "both directions"), (":", 1, "forward"), ("--", 1, "backward")):
            handles.append(Line2D([], [], color="0.3", ls=style, lw=lw))
            labels.append(what)
    if handles:
        fig.legend(handles, labels, fontsize=8, loc="outside right upper", frameon=False)
    return fig


def _sorted(values: pd.Series, log: bool) -> np.ndarray:
    v = np.sort(values.dropna().to_numpy(float))
    return v[v > 0] if log else v


# the heat-map's cells that hold no value: what they are, how they are drawn
FAILED, NO_VALUE, NOT_PLANNED = 1, 2, 3
CELL_KINDS = {
    FAILED: ("#b2182b", "failed (the method's failure)"),
    NO_VALUE: ("0.78", "no value (pending, infrastructure failure or not evaluable)"),
    NOT_PLANNED: ("white", "not planned (no such run)"),
}


def heatmap_cells(
    df: pd.DataFrame, metric: str
) -> tuple[list[str], list[tuple[str, str, str]], np.ndarray, np.ndarray]:
    """Methods (rows), columns (sequence, direction, trial; forward first, trials in order), each cell's value
    (NaN where none) and kind (0 value, FAILED, NO_VALUE, NOT_PLANNED: no row of the table is that run)."""
    d = df.assign(
        sequence=df.sequence.astype(str),
        direction=df.direction.astype(str),
        trial=df.trial.map(lambda t: str(int(t)) if isinstance(t, int | float | np.number) and t == t else str(t)),
    )
    methods = sorted(d.method.astype(str).unique())

    def order(c: tuple[str, str, str]):
        seq, direction, trial = c
        return seq, {"forward": 0, "backward": 1}.get(direction, 2), direction, int(trial) if trial.isdigit() else 0

    cols = sorted(set(zip(d.sequence, d.direction, d.trial, strict=True)), key=order)
    where = {c: i for i, c in enumerate(cols)}
    values = np.full((len(methods), len(cols)), np.nan)
    kinds = np.full((len(methods), len(cols)), NOT_PLANNED)
    status = d["status"] if "status" in d.columns else pd.Series("done", index=d.index)
    failure = d["failure"] if "failure" in d.columns else pd.Series(None, index=d.index)
    for method, seq, direction, trial, value, st, why in zip(
        d.method.astype(str), d.sequence, d.direction, d.trial, d[metric], status, failure, strict=True
    ):
        i, j = methods.index(method), where[(seq, direction, trial)]
        if st == "done" and np.isfinite(value):
            values[i, j], kinds[i, j] = value, 0
        elif st == "failed" and why not in INFRA_FAILURES:
            kinds[i, j] = FAILED
        else:
            kinds[i, j] = NO_VALUE
    return methods, cols, values, kinds


def heatmap(
    df: pd.DataFrame, folder: Path, metric: str = MAIN, label: str = "", names: dict[str, str] | None = None
) -> Path:
    """The heat map of `metric` (heatmap_figure), saved in `folder`."""
    return save(heatmap_figure(df, metric, label, names), folder, f"heatmap_{metric}")


def colour_norm(finite: np.ndarray) -> Normalize:
    """The heat map's colour scale. Values spanning a decade or more: logarithmic, from the least to the greatest.
    Otherwise linear from zero (an error's origin) to the greatest, so that colours differ as much as the values'
    ratio does: 0.0282 and 0.0300 are two close colours, not the scale's two ends (a min-max scale made a 6 %
    difference look like the whole range). Values below zero: linear from the least."""
    if not len(finite):
        return Normalize(0, 1)
    if use_log_scale(finite):
        return LogNorm(finite.min(), finite.max())
    low = min(0.0, float(finite.min()))
    return Normalize(low, max(float(finite.max()), low + 1e-12))


def heatmap_figure(
    df: pd.DataFrame, metric: str = MAIN, label: str = "", names: dict[str, str] | None = None
) -> plt.Figure:
    """Colour-coded error per method (rows) and run (columns: sequence at the top, direction and trial below);
    failed runs, runs without a value and runs never planned (a method with fewer trials or directions) each drawn
    apart and named in the legend; the colour scale as colour_norm says."""
    methods, cols, values, kinds = heatmap_cells(df, metric)
    col_pt = 9.0 if len(cols) <= 130 else max(1.0, 1100 / len(cols))  # room for one label per column when few
    width = min(18.0, max(5.5, 2.8 + len(cols) * col_pt / 72))
    fig, ax = plt.subplots(figsize=(width, 2.6 + 0.32 * len(methods)), layout="constrained")
    finite = values[np.isfinite(values)]
    norm = colour_norm(finite)
    log = isinstance(norm, LogNorm)
    im = ax.imshow(np.ma.masked_invalid(values), aspect="auto", cmap="viridis", norm=norm, interpolation="nearest")
    colours = [CELL_KINDS[k][0] for k in (FAILED, NO_VALUE, NOT_PLANNED)]
    empty = np.ma.masked_where(kinds == 0, kinds)
    ax.imshow(empty, aspect="auto", cmap=ListedColormap(colours), vmin=0.5, vmax=3.5, interpolation="nearest")
    for i in range(len(methods)):  # not planned: hatched, one rectangle per stretch of such cells
        j = 0
        while j < len(cols):
            if kinds[i, j] == NOT_PLANNED:
                k = j
                while k < len(cols) and kinds[i, k] == NOT_PLANNED:
                    k += 1
                ax.add_patch(Rectangle((j - 0.5, i - 0.5), k - j, 1, fill=False, hatch="///", ec="0.6", lw=0))
                j = k
            else:
                j += 1
    ax.set_yticks(range(len(methods)), [(names or {}).get(m, m) for m in methods])
    _heatmap_columns(ax, cols, col_pt)
    cbar = fig.colorbar(im, ax=ax, label=LABELS.get(metric, metric) + (" (log scale)" if log else ""))
    if log:
        readable_log_ticks(cbar.ax.yaxis, finite.min(), finite.max())
    handles = [Patch(fc=CELL_KINDS[k][0], ec="0.5", label=CELL_KINDS[k][1]) for k in (FAILED, NO_VALUE)]
    handles.append(Patch(fc="white", ec="0.6", hatch="///", label=CELL_KINDS[NOT_PLANNED][1]))
    fig.legend(handles=handles, loc="outside lower center", ncol=3, fontsize=7, frameon=False)
    ax.set_title(_labelled(label, f"{LABELS.get(metric, metric)} of each run"), fontsize=9)
    return fig


def _heatmap_columns(ax, cols: list[tuple[str, str, str]], col_pt: float) -> None:
    """Column labels: each run's direction and trial below (f0, b2; where they fit, else each direction's block),
    each sequence at the top, lines between sequences and between directions."""
    seqs = [c[0] for c in cols]
    starts = [i for i, s in enumerate(seqs) if i == 0 or s != seqs[i - 1]]
    blocks = [i for i, c in enumerate(cols) if i == 0 or c[:2] != cols[i - 1][:2]]
    for i in blocks[1:]:
        ax.axvline(i - 0.5, color="white", lw=2.0 if i in starts else 0.8)
    if col_pt >= 7:
        ax.set_xticks(range(len(cols)), [f"{c[1][:1]}{c[2]}" for c in cols], rotation=90, fontsize=6)
        what = "each column one run: direction (f forward, b backward) and trial"
    else:
        ends = [*blocks[1:], len(cols)]
        wide = [(a, b) for a, b in zip(blocks, ends, strict=True) if (b - a) * col_pt >= 8]
        short = {"forward": "fw", "backward": "bw"}
        names = [short.get(cols[a][1], cols[a][1]) for a, _ in wide]
        ax.set_xticks([(a + b - 1) / 2 for a, b in wide], names, rotation=90, fontsize=6)
        what = "runs by direction (fw forward, bw backward), trials in order"
    ax.set_xlabel(what + "; sequences at the top", fontsize=7)
    ends = [*starts[1:], len(cols)]
    step = max(1, math.ceil(8 / max(col_pt * min(b - a for a, b in zip(starts, ends, strict=True)), 1e-9)))
    top = ax.secondary_xaxis("top")
    shown = starts[::step]
    top.set_xticks([(a + ends[starts.index(a)] - 1) / 2 for a in shown], [seqs[a] for a in shown], rotation=90)
    top.tick_params(labelsize=6, length=0)


def boxplot(
    st: StudyStats,
    metric: str,
    folder: Path,
    label: str = "",
    adjust: str = "holm",
    alpha: float = 0.05,
    names: dict[str, str] | None = None,
):
    """Box plots of a metric per method (outliers removed; best median at the top), each method's letter group in a
    column inside the axes at the right, beside its box (methods sharing a letter do not differ); the title holds
    Kruskal-Wallis' chi-square, df and p."""
    s = st.metrics[metric]
    methods = sorted(s.medians, key=lambda m: s.medians[m])
    values = st.kept[metric].to_numpy(float)
    data = [values[(st.kept.method == m).to_numpy() & np.isfinite(values)] for m in methods]  # this metric's runs
    fig, ax = plt.subplots(figsize=(6.4, 1.7 + 0.42 * len(methods)), layout="constrained")
    positions = list(range(len(methods), 0, -1))
    parts = ax.boxplot(data, positions=positions, showfliers=False, widths=0.55, **HORIZONTAL)
    ends = np.concatenate([w.get_xdata() for w in parts["whiskers"]] or [np.zeros(1)])
    lo, hi = float(np.nanmin(ends)), float(np.nanmax(ends))
    span = hi - lo or abs(hi) or 1.0
    ax.set_xlim(lo - 0.05 * span, hi + 0.16 * span + 0.02 * span * max(len(v) for v in s.letters.values() or [""]))

    def tick(m: str, values: np.ndarray) -> str:
        cov = st.coverage.get(m)
        shown = (names or {}).get(m, m)
        return f"{shown} (n={len(values)}" + (
            f", coverage {100 * cov:.0f} %)" if cov is not None and cov == cov else ")"
        )

    ax.set_yticks(positions, [tick(m, v) for m, v in zip(methods, data, strict=True)])
    for pos, m in zip(positions, methods, strict=True):
        ax.annotate(
            s.letters.get(m, ""),
            xy=(1, pos),
            xycoords=("axes fraction", "data"),
            xytext=(-5, 0),
            textcoords="offset points",
            ha="right",
            va="center",
            fontsize=10,
            fontweight="bold",
        )
    ax.set_xlabel(LABELS.get(metric, metric))
    ax.grid(True, axis="x", alpha=0.3)
    test = f"Kruskal-Wallis chi2 = {s.kruskal_chi2:.4g}, df = {s.kruskal_df}, p = {s.kruskal_p:.3g}"
    groups = f"letters (right): Wilcoxon rank-sum, {adjust}, alpha {alpha:g}"
    ax.set_title(_labelled(label, LABELS.get(metric, metric)) + f"\n{test}; {groups}", fontsize=8)
    return save(fig, folder, f"box_{metric}")


def trajectories(paths: SequencePaths, folder: Path, label: str = "", names: dict[str, str] | None = None) -> Path:
    """Top view of each method's best, median and worst run (by the paths' metric) over the ground truth, one panel
    per method: the ground truth's two most spread coordinates, equal aspect, in the ground truth's units; the
    start and the end of the ground truth marked; one legend for what the panels draw."""
    methods = list(dict.fromkeys(r.method for r in paths.runs))
    ncols = min(3, len(methods))
    nrows = math.ceil(len(methods) / ncols)
    fig, axes = plt.subplots(
        nrows, ncols, figsize=(4.0 * ncols + 0.6, 3.9 * nrows + 1.0), squeeze=False, layout="constrained"
    )
    a, b = paths.plane()
    axes_names = "xyz"
    for ax in axes.flat[len(methods) :]:
        ax.set_visible(False)
    for ax, method in zip(axes.flat, methods, strict=False):
        if paths.full is not None:
            ax.plot(paths.full[:, a], paths.full[:, b], "-", color="0.86", lw=5, label="ground truth, whole path")
        ax.plot(paths.gt[:, a], paths.gt[:, b], "-", color="0.55", lw=3, label=paths.gt_label())
        for run in paths.runs:
            if run.method == method:
                color, style, lw = PICK_STYLES[run.which]
                ax.plot(run.positions[:, a], run.positions[:, b], style, color=color, lw=lw, label=f"{run.which} run")
        start, end = paths.ends()  # the start drawn over the end: a loop's two markers both show
        ax.plot(*end[[a, b]], marker="s", mfc="white", mec="black", ms=10, ls="none", label="end (ground truth)")
        ax.plot(*start[[a, b]], marker="^", color="black", ms=6, ls="none", label="start (ground truth)")
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel(f"{axes_names[a]} ({paths.units})")
        ax.set_ylabel(f"{axes_names[b]} ({paths.units})")
        ax.set_title((names or {}).get(method, method), fontsize=9)
        ax.grid(True, alpha=0.25)
    handles: dict[str, object] = {}
    for ax in axes.flat[: len(methods)]:
        for h, lab in zip(*ax.get_legend_handles_labels(), strict=True):
            handles.setdefault(lab, h)
    fig.legend(handles.values(), handles.keys(), loc="outside lower center", ncol=min(4, len(handles)), fontsize=8)
    title = f"{paths.sequence}: best, median and worst run of each method by {paths.metric}, {paths.aligned_by()}"
    fig.suptitle(_labelled(label, title), fontsize=9)
    return save(fig, folder, f"trajectories_{paths.sequence}")


def robustness(
    df: pd.DataFrame,
    kind: str,
    metrics: list[str],
    folder: Path,
    label: str = "",
    colours: dict[str, str] | None = None,
) -> Path:
    """The robustness figure of one perturbation kind (robustness_figure), saved in `folder`."""
    from slamrun.datasets.perturb import file_tag

    return save(robustness_figure(df, kind, metrics, label, colours), folder, f"robustness_{file_tag(kind)}")


ROBUST_FONT = 10  # points: at the report's width (1180 px) a robustness figure is shown about 1:1, 15 px text


def robustness_figure(
    df: pd.DataFrame, kind: str, metrics: list[str], label: str = "", colours: dict[str, str] | None = None
) -> plt.Figure:
    """Against the level of `kind` (baseline first, mildest to most severe): the success rate; paired against each
    method's own baseline on its main metric, the area and the median ratio (failures at infinity, drawn on the
    panel's top edge); then per metric the median of its evaluated runs, with the band between the first and third
    quartiles (the spread over trials, sequences and directions); a level where a method has no evaluated run has
    no point (its success rate says why)."""
    from slamrun.analysis.load import main_metric
    from slamrun.analysis.robustness import paired_table, spread, success_rates
    from slamrun.datasets.perturb import kind_of, title_of

    rates = success_rates(df)
    rates = rates[rates.perturbation == kind]
    names = list(dict.fromkeys(rates.level)) or ["none"]
    metric = main_metric(df)
    paired = paired_table(df, metric, only=kind) if metric else pd.DataFrame(columns=["method"])
    panels = ["success", *(["area", "ratio"] if not paired.empty else []), *metrics]
    cols = min(len(panels), 3)
    rows = math.ceil(len(panels) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.0 * cols + 1.8, 2.6 * rows), layout="constrained", squeeze=False)
    methods = sorted(df.method.unique())
    colors = {**method_colours(methods), **(colours or {})}
    x = np.arange(len(names))
    for ax, panel in zip(axes.flat, panels, strict=False):
        for m in methods:
            if panel in ("success", "area", "ratio"):
                _robustness_line(ax, panel, rates[rates.method == m], paired[paired.method == m], names, colors[m], m)
                continue
            s = spread(df, kind, panel)
            s = s[s.method == m]
            if s.empty:
                continue
            ax.fill_between(s.position, s.q1, s.q3, color=colors[m], alpha=0.15, lw=0)
            ax.plot(s.position, s["median"], "o-", color=colors[m], lw=1.6, ms=4)
        if panel == "success":
            ax.set_ylim(-3, 103)
            ax.set_ylabel("success rate (%)", fontsize=ROBUST_FONT)
            ax.axhline(50, color="0.5", lw=0.8, ls=":")
        elif panel == "area":
            ax.set_ylim(-0.03, 1.03)
            ax.set_ylabel("area, paired (0-1)", fontsize=ROBUST_FONT)
        elif panel == "ratio":
            _ratio_axis(ax, paired["median ratio"].to_numpy(float))
        else:
            values = spread(df, kind, panel)[["q1", "q3"]].to_numpy(float).ravel()
            if use_log_scale(values):
                ax.set_yscale("log")
            ax.set_ylabel(LABELS.get(panel, panel), fontsize=ROBUST_FONT)
        ax.set_xticks(x, names, fontsize=ROBUST_FONT)
        ax.tick_params(axis="y", labelsize=ROBUST_FONT)
        ax.set_xlim(-0.3, len(names) - 0.7)
        ax.grid(True, alpha=0.3)
    for ax in list(axes.flat)[len(panels) :]:
        ax.set_visible(False)
    k = kind_of(kind)
    fig.supxlabel(f"{title_of(k.name)}: {k.parameter} ({k.unit}), mildest to most severe", fontsize=ROBUST_FONT)
    title = f"robustness to {title_of(kind)}"
    fig.suptitle(_labelled(label, title), fontsize=ROBUST_FONT + 1)
    handles, labels = axes.flat[0].get_legend_handles_labels()
    if handles:
        fig.legend(handles, labels, fontsize=ROBUST_FONT, loc="outside right upper", frameon=False)
    return fig


def _robustness_line(ax, panel: str, rates: pd.DataFrame, paired: pd.DataFrame, names: list[str], colour, m) -> None:
    """One method's line on the success, area or median-ratio panel (the baseline is ratio 1, area 1 by definition:
    the paired panels start at the first perturbed level)."""
    if panel == "success":
        ax.plot([names.index(v) for v in rates.level], rates["success %"], "o-", color=colour, lw=1.6, ms=4, label=m)
        return
    if paired.empty:
        return
    at = [names.index(v) for v in paired.level]
    if panel == "area":
        ax.plot(at, paired["area"], "o-", color=colour, lw=1.6, ms=4)
        return
    r = paired["median ratio"].to_numpy(float)
    ax.plot(at, np.where(np.isinf(r), np.nan, r), "o-", color=colour, lw=1.6, ms=4)
    failed = [a for a, v in zip(at, r, strict=True) if np.isinf(v)]
    if failed:  # placed on the top edge once the axis is set (_ratio_axis)
        ax.plot(failed, [np.nan] * len(failed), "x", color=colour, ms=7, mew=2, gid="failed")


def _ratio_axis(ax, ratios: np.ndarray) -> None:
    """The median-ratio panel's log axis from the values drawn, and failures (inf) on its top edge."""
    finite = ratios[np.isfinite(ratios) & (ratios > 0)]
    lo = min(0.5, float(finite.min()) * 0.9) if finite.size else 0.5  # 0.5 to 5 at least: four labelled ticks
    hi = max(5.0, float(finite.max()) * 1.3) if finite.size else 5.0
    ax.set_yscale("log")
    ax.set_ylim(lo, hi)
    readable_log_ticks(ax.yaxis, lo, hi)
    ax.axhline(1.0, color="0.5", lw=0.8, ls=":")
    for line in ax.get_lines():
        if line.get_gid() == "failed":
            line.set_ydata([hi] * len(line.get_xdata()))
            line.set_clip_on(False)
    ax.set_ylabel("median ratio to baseline\n(x on top: failed)", fontsize=ROBUST_FONT)


def robustness_curves(
    df: pd.DataFrame, kind: str, folder: Path, label: str = "", colours: dict[str, str] | None = None
) -> Path | None:
    """The cumulative curves of one kind's paired ratios (robustness_curves_figure), saved; None without pairs."""
    fig = robustness_curves_figure(df, kind, label, colours)
    from slamrun.datasets.perturb import file_tag

    return None if fig is None else save(fig, folder, f"robustness_curves_{file_tag(kind)}")


def robustness_curves_figure(
    df: pd.DataFrame, kind: str, label: str = "", colours: dict[str, str] | None = None
) -> plt.Figure | None:
    """Per level of `kind`, each method's share of pairs whose ratio to its baseline is at most x, for x from 1 to
    AREA_BOUND on a log axis: failures are never counted, so a curve ends under 1 by its failures; its area over the
    axis' width is the paired table's area."""
    from slamrun.analysis.load import main_metric
    from slamrun.analysis.robustness import AREA_BOUND, pairs, series
    from slamrun.datasets.perturb import kind_of, title_of

    metric = main_metric(df)
    if metric is None:
        return None
    p = pairs(df, kind, metric).dropna(subset=["ratio"])
    levels = [name for name, _ in series(df, kind)[1:] if (p.level == name).any()]
    if not levels:
        return None
    cols = min(len(levels), 3)
    rows = math.ceil(len(levels) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.0 * cols + 1.8, 2.6 * rows), layout="constrained", squeeze=False)
    methods = sorted(df.method.unique())
    colors = {**method_colours(methods), **(colours or {})}
    grid = np.geomspace(1.0, AREA_BOUND, 200)
    for ax, name in zip(axes.flat, levels, strict=False):
        at = p[p.level == name]
        for m in methods:
            r = at.loc[at.method == m, "ratio"].to_numpy(float)
            if r.size == 0:
                continue
            share = (r[None, :] <= grid[:, None]).mean(axis=1)
            ax.step(grid, share, where="post", color=colors[m], lw=1.6, label=m)
        ax.set_xscale("log")
        ax.set_xlim(1.0, AREA_BOUND)
        ax.set_ylim(-0.03, 1.03)
        readable_log_ticks(ax.xaxis, 1.0, AREA_BOUND)
        ax.set_title(f"{kind_of(kind).parameter} {name}", fontsize=ROBUST_FONT)
        ax.tick_params(labelsize=ROBUST_FONT)
        ax.grid(True, alpha=0.3)
    for ax in axes[:, 0]:
        ax.set_ylabel("share of pairs", fontsize=ROBUST_FONT)
    for ax in list(axes.flat)[len(levels) :]:
        ax.set_visible(False)
    fig.supxlabel(f"x: {LABELS.get(metric, metric)} over the method's own baseline's (log)", fontsize=ROBUST_FONT)
    fig.suptitle(_labelled(label, f"robustness to {title_of(kind)}: pairs within x"), fontsize=ROBUST_FONT + 1)
    handles, labels = axes.flat[0].get_legend_handles_labels()
    if handles:
        fig.legend(handles, labels, fontsize=ROBUST_FONT, loc="outside right upper", frameon=False)
    return fig
