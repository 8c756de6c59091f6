"""The study's tables as DataFrames, and their CSV, Markdown and LaTeX forms."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

from runner.analysis.stats import StudyStats


def medians_with_letters(st: StudyStats, metrics: list[str]) -> pd.DataFrame:
    """Table 3/4 layout: one row per method (best first by the first metric), 'median letters' cells,
    and a last row with the Kruskal-Wallis chi-square of each metric."""
    first = st.metrics[metrics[0]]
    methods = sorted(first.medians, key=lambda m: first.medians[m])
    rows = []
    for m in methods:
        row = {"method": m}
        for metric in metrics:
            s = st.metrics[metric]
            row[metric] = f"{s.medians[m]:.6g} {s.letters.get(m, '')}" if m in s.medians else "-"
        rows.append(row)
    rows.append({"method": "Kruskal-Wallis chi2", **{k: f"{st.metrics[k].kruskal_chi2:.5g}" for k in metrics}})
    return pd.DataFrame(rows)


def resources_table(df: pd.DataFrame) -> pd.DataFrame:
    """Table 2 layout: mean resources per method over its runs."""
    cols = {
        "cpu_mean_pct": "CPU mean %",
        "cpu_peak_pct": "CPU peak %",
        "gpu_util_mean_pct": "GPU %",
        "gpu_mem_peak_mb": "GPU mem MB",
        "ram_peak_mb": "RAM peak MB",
        "wall_s": "time (s)",
        "fps": "FPS",
    }
    present = [c for c in cols if c in df.columns]
    out = df.groupby("method")[present].mean().reset_index().rename(columns=cols)
    out.insert(1, "runs", df.groupby("method").size().to_numpy())
    return out


def motion_bias_table(df: pd.DataFrame, metric: str = "e_align") -> pd.DataFrame:
    """Forward vs backward medians per method, with the Wilcoxon rank-sum p-value between directions."""
    rows = []
    for m, g in df.dropna(subset=[metric]).groupby("method", sort=True):
        fw = g.loc[g.direction == "forward", metric].to_numpy(float)
        bw = g.loc[g.direction == "backward", metric].to_numpy(float)
        p = stats.mannwhitneyu(fw, bw).pvalue if len(fw) and len(bw) else np.nan
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
    `metric`, and whether they differ (Wilcoxon rank-sum, alpha 0.05)."""
    rows = []
    labels = set(df.method.dropna().astype(str))
    for published in sorted(lab for lab in labels if ":" in lab):
        own = published.split(":", 1)[1]
        if own not in labels:
            continue
        new = df.loc[(df.method == own), metric].dropna().to_numpy(float)
        old = df.loc[(df.method == published), metric].dropna().to_numpy(float)
        p = stats.mannwhitneyu(new, old).pvalue if len(new) and len(old) else np.nan
        rows.append(
            {
                "method": own,
                "published as": published,
                f"median {metric} (new)": np.median(new) if len(new) else np.nan,
                f"median {metric} (published)": np.median(old) if len(old) else np.nan,
                "n new": len(new),
                "n published": len(old),
                "p (rank-sum)": p,
                "different at 0.05": bool(p < 0.05) if np.isfinite(p) else None,
            }
        )
    return pd.DataFrame(rows)


def per_sequence_table(df: pd.DataFrame, metric: str = "e_align") -> pd.DataFrame:
    """Median of a metric per method (rows) and sequence (columns)."""
    d = df.dropna(subset=[metric])
    if d.empty:
        return pd.DataFrame()
    return d.pivot_table(index="method", columns="sequence", values=metric, aggfunc="median").reset_index()


def to_markdown(df: pd.DataFrame) -> str:
    cells = [[_cell(v) for v in row] for row in df.itertuples(index=False)]
    head = "| " + " | ".join(map(str, df.columns)) + " |\n|" + "---|" * len(df.columns) + "\n"
    return head + "".join("| " + " | ".join(r) + " |\n" for r in cells)


def to_latex(df: pd.DataFrame, caption: str = "") -> str:
    def esc(s: str) -> str:
        for a, b in (("\\", r"\textbackslash{}"), ("_", r"\_"), ("%", r"\%"), ("&", r"\&"), ("#", r"\#")):
            s = s.replace(a, b)
        return s

    cols = "l" + "r" * (len(df.columns) - 1)
    lines = [
        r"\begin{table}[t]",
        r"\centering",
        rf"\begin{{tabular}}{{{cols}}}",
        r"\hline",
        " & ".join(esc(str(c)) for c in df.columns) + r" \\",
        r"\hline",
    ]
    lines += [" & ".join(esc(_cell(v)) for v in row) + r" \\" for row in df.itertuples(index=False)]
    lines += [r"\hline", r"\end{tabular}"]
    if caption:
        lines.append(rf"\caption{{{esc(caption)}}}")
    lines.append(r"\end{table}")
    return "\n".join(lines) + "\n"


def to_html(df: pd.DataFrame) -> str:
    import html

    head = "".join(f"<th>{html.escape(str(c))}</th>" for c in df.columns)
    body = "".join(
        "<tr>" + "".join(f"<td>{html.escape(_cell(v))}</td>" for v in row) + "</tr>"
        for row in df.itertuples(index=False)
    )
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def write_all(df: pd.DataFrame, folder: Path, name: str, caption: str = "") -> None:
    folder.mkdir(parents=True, exist_ok=True)
    df.to_csv(folder / f"{name}.csv", index=False)
    (folder / f"{name}.md").write_text(to_markdown(df))
    (folder / f"{name}.tex").write_text(to_latex(df, caption))


def _cell(v) -> str:
    if isinstance(v, float | np.floating):
        return "-" if not np.isfinite(v) else f"{v:.4g}"
    return str(v)
