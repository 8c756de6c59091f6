"""The study's figures from DataFrames (matplotlib, headless): PNG and SVG files."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import matplotlib.ticker  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from runner.analysis.stats import StudyStats  # noqa: E402
from runner.results.vocabulary import LABELS  # noqa: E402


def save(fig, folder: Path, name: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    fig.savefig(folder / f"{name}.png", dpi=110, bbox_inches="tight")
    fig.savefig(folder / f"{name}.svg", bbox_inches="tight")
    plt.close(fig)
    return folder / f"{name}.png"


def _labelled(label: str, title: str) -> str:
    """A figure's title headed by its dataset, where it has one."""
    return f"{label}: {title}" if label else title


def _colors(methods: list[str]) -> dict[str, tuple]:
    cmap = plt.get_cmap("tab10" if len(methods) <= 10 else "tab20")
    return {m: cmap(i % cmap.N) for i, m in enumerate(methods)}


def cumulative(
    df: pd.DataFrame, metric: str, folder: Path, name: str | None = None, bold_all: bool = False, label: str = ""
) -> Path:
    """Runs (y) whose error is below x (log x), one curve per method: best methods reach the top left; `label`
    (the dataset) heads the title."""
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    methods = sorted(df.method.unique())
    colors = _colors(methods)
    for m in methods:
        g = df[df.method == m]
        if bold_all and "direction" in g:
            for direction, style in (("forward", ":"), ("backward", "--")):
                v = np.sort(g.loc[g.direction == direction, metric].dropna().to_numpy(float))
                if len(v):
                    ax.step(v, np.arange(1, len(v) + 1), where="post", ls=style, lw=1, color=colors[m])
        v = np.sort(g[metric].dropna().to_numpy(float))
        v = v[v > 0]
        if len(v):
            ax.step(v, np.arange(1, len(v) + 1), where="post", lw=2.2 if bold_all else 1.6, color=colors[m], label=m)
    ax.set_xscale("log")
    ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.set_xlabel(LABELS.get(metric, metric))
    ax.set_ylabel("number of runs")
    title = _labelled(label, f"cumulative {LABELS.get(metric, metric)}")
    ax.set_title(title + (" (dotted forward, dashed backward, bold both)" if bold_all else ""), fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    return save(fig, folder, name or f"cumulative_{metric}")


def heatmap(df: pd.DataFrame, folder: Path, metric: str = "e_align", label: str = "") -> Path:
    """Colour-coded error per method (rows) × sequence, direction and run (columns); grey = failed."""
    d = df.copy()
    d["col"] = d.sequence.astype(str) + "/" + d.direction.astype(str).str[0] + "/" + d.trial.astype(str)
    cols = sorted(d["col"].unique())
    methods = sorted(d.method.unique())
    grid = d.pivot_table(index="method", columns="col", values=metric, aggfunc="first").reindex(
        index=methods, columns=cols
    )
    values = np.log10(grid.to_numpy(float))
    fig, ax = plt.subplots(figsize=(min(18, 3 + 0.05 * len(cols)), 1 + 0.45 * len(methods)))
    cmap = plt.get_cmap("viridis").with_extremes(bad="0.85")  # grey where a run has no value
    im = ax.imshow(np.ma.masked_invalid(values), aspect="auto", cmap=cmap, interpolation="nearest")
    ax.set_yticks(range(len(methods)), methods)
    seqs = [c.split("/")[0] for c in cols]
    starts = [i for i, s in enumerate(seqs) if i == 0 or s != seqs[i - 1]]
    ax.set_xticks(starts, [seqs[i] for i in starts], rotation=90, fontsize=6)
    fig.colorbar(im, ax=ax, label=f"log10 {metric}")
    ax.set_title(_labelled(label, f"{LABELS.get(metric, metric)} per run (grey: no evaluated run)"), fontsize=9)
    return save(fig, folder, f"heatmap_{metric}")


def boxplot(st: StudyStats, metric: str, folder: Path, label: str = "") -> Path:
    """Box plots of a metric per method (outliers removed), medians labelled with their letters."""
    s = st.metrics[metric]
    methods = sorted(s.medians, key=lambda m: s.medians[m])
    data = [st.kept.loc[st.kept.method == m, metric].to_numpy(float) for m in methods]
    fig, ax = plt.subplots(figsize=(max(5, 0.9 * len(methods)), 4))
    ax.boxplot(data, showfliers=False)
    ax.set_xticks(range(1, len(methods) + 1), methods, rotation=30, ha="right")
    top = max((np.percentile(v, 75) + 1.5 * (np.percentile(v, 75) - np.percentile(v, 25))) for v in data if len(v))
    for i, m in enumerate(methods, start=1):
        ax.text(i, top, s.letters.get(m, ""), ha="center", va="bottom", fontsize=10, fontweight="bold")
    ax.set_ylabel(LABELS.get(metric, metric))
    ax.set_title(
        _labelled(label, f"{LABELS.get(metric, metric)}: Kruskal-Wallis chi2 = {s.kruskal_chi2:.4g}"), fontsize=9
    )
    return save(fig, folder, f"box_{metric}")


def trajectories(
    runs: list[tuple[str, str, object]], gt, full, folder: Path, name: str, metric: str, label: str = ""
) -> Path:
    """Per method, its best, median and worst run by `metric` over the ground truth, top view: aligned as the
    metric aligns them (ATE: a Sim(3) over every pose with ground truth; e_align: the start segment's Sim(3)).
    `full` is the whole ground-truth path where the sequence has one (groundtruth_full.txt), else None."""
    from runner.core.alignment import align_sim3
    from runner.core.evaluation import associate

    methods = list(dict.fromkeys(r[0] for r in runs))
    fig, axes = plt.subplots(1, len(methods), figsize=(4.2 * len(methods), 4.4), squeeze=False)
    valid = np.isfinite(gt.positions).all(axis=1)
    n = len(gt)
    styles = {"best": ("-", 1.4), "median": ("--", 1.1), "worst": (":", 1.1)}
    for ax, method in zip(axes[0], methods, strict=True):
        if full is not None:
            ax.plot(full.positions[:, 0], full.positions[:, 1], "-", color="0.75", lw=3, label="ground truth")
        for seg, color in ((slice(0, n // 2), "k"), (slice(n // 2, n), "0.4")):
            idx = np.flatnonzero(valid[seg]) + (seg.start or 0)
            ax.plot(gt.positions[idx, 0], gt.positions[idx, 1], ".", color=color, ms=2.5)
        for label, which, traj in runs:
            if label != method:
                continue
            match = associate(gt.timestamps, traj.timestamps)
            use = (match >= 0) & valid[np.maximum(match, 0)]
            if metric == "e_align":
                use &= match < n // 2
            if use.sum() < 3:
                continue
            sim = align_sim3(traj.positions[use], gt.positions[match[use]])
            p = sim.apply(traj.positions)
            style, lw = styles[which]
            ax.plot(p[:, 0], p[:, 1], style, lw=lw, color="C0", label=which)
        ax.set_aspect("equal", adjustable="datalim")
        ax.legend(fontsize=7)
        ax.set_title(f"{method}", fontsize=9)
    how = "Sim(3) over all poses (ATE)" if metric != "e_align" else "the start segment's Sim(3)"
    title = f"{name}: best, median and worst run by {metric}, aligned by {how}; dots: ground truth"
    fig.suptitle(_labelled(label, title), fontsize=8)
    return save(fig, folder, f"trajectories_{name}")
