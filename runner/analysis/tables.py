"""The study's tables as DataFrames, and their CSV, Markdown and LaTeX forms."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

from runner.analysis.stats import StudyStats


def medians_with_letters(st: StudyStats, metrics: list[str]) -> pd.DataFrame:
    """Table 3/4 layout: one row per method (best first by the first metric), 'median letters' cells,
    and last rows with the Kruskal-Wallis chi-square, degrees of freedom and p-value of each metric."""
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
    rows.append({"method": "Kruskal-Wallis df", **{k: str(st.metrics[k].kruskal_df) for k in metrics}})
    rows.append({"method": "Kruskal-Wallis p", **{k: _p(st.metrics[k].kruskal_p) for k in metrics}})
    return pd.DataFrame(rows)


def _p(p: float) -> str:
    return "-" if not np.isfinite(p) else f"{p:.3g}"


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
                "different at 0.05": _words(p < 0.05) if np.isfinite(p) else "not known",
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
    """The table as HTML."""
    import html

    # a long column name may break after an underscore: the table keeps to the page's width
    head = "".join(f"<th>{html.escape(str(c)).replace('_', '_<wbr>')}</th>" for c in df.columns)
    body = "".join(
        "<tr>" + "".join(f"<td>{html.escape(_cell(v))}</td>" for v in row) + "</tr>"
        for row in df.itertuples(index=False)
    )
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def write_all(df: pd.DataFrame, folder: Path, name: str, caption: str = "", note: str = "") -> None:
    """The table as CSV, Markdown and LaTeX (`caption` its LaTeX caption); `note`, what its values are, heads the
    Markdown and LaTeX files as a comment (the files paste as they are)."""
    folder.mkdir(parents=True, exist_ok=True)
    df.to_csv(folder / f"{name}.csv", index=False)
    what = " ".join(f"{caption}. {note}".split()) if note else ""
    (folder / f"{name}.md").write_text((f"<!-- {what.replace('--', '- -')} -->\n" if what else "") + to_markdown(df))
    (folder / f"{name}.tex").write_text((f"% {what}\n" if what else "") + to_latex(df, caption))


def _cell(v) -> str:
    if isinstance(v, float | np.floating):
        return "-" if not np.isfinite(v) else f"{v:.4g}"
    return str(v)
