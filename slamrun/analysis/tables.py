"""The study's tables as DataFrames, and their CSV, Markdown and LaTeX forms."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

from slamrun.analysis.stats import StudyStats
from slamrun.results.vocabulary import played

LETTERS = " letters"  # the suffix of a medians column's letter groups
KRUSKAL_ROWS = ("Kruskal-Wallis chi2", "Kruskal-Wallis df", "Kruskal-Wallis p")


def medians_with_letters(st: StudyStats, metrics: list[str]) -> pd.DataFrame:
    """Table 3/4 layout, numeric: one row per method (best first by the first metric) with the runs counted (copies
    once), the median coverage of those runs (the share of the sequence's frames with a pose), and per metric its
    median and, in a column of its own, its letter groups; last rows: the Kruskal-Wallis chi-square, degrees of
    freedom and p-value of each metric."""
    first = st.metrics[metrics[0]]
    methods = sorted(first.medians, key=lambda m: first.medians[m])
    kept = st.kept
    rows = []
    for m in methods:
        runs = kept[kept["method"] == m] if "method" in kept.columns else kept.iloc[0:0]
        row: dict = {"method": m, "runs": len(runs)}
        if "coverage" in kept.columns:
            row["coverage"] = float(runs["coverage"].median()) if runs["coverage"].notna().any() else np.nan
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
    cols = {
        "cpu_mean_pct": "CPU mean %",
        "cpu_peak_pct": "CPU peak %",
        "gpu_util_mean_pct": "GPU %",
        "gpu_mem_peak_mb": "GPU mem MB",
        "ram_peak_mb": "RAM peak MB",
        "wall_s": "time (s)",
        "fps": "FPS",
        "cpu_wait_pct": "CPU wait %",
        "host_cpu_pressure_pct": "machine CPU pressure %",
    }
    present = [c for c in cols if c in df.columns]
    out = df.groupby("method")[present].mean().reset_index().rename(columns=cols)
    out.insert(1, "runs", df.groupby("method").size().to_numpy())
    if contention_pct is not None and "cpu_wait_pct" in df.columns:
        own = df["cpu_wait_own_pct"].fillna(0.0) if "cpu_wait_own_pct" in df.columns else 0.0
        over = (df["cpu_wait_pct"] - own > contention_pct).groupby(df["method"]).sum()
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


def to_latex(df: pd.DataFrame, caption: str = "", label: str = "", lower_is_better: tuple[str, ...] = ()) -> str:
    """The table for a paper (booktabs): headers in words with their units, each numeric column at one number of
    decimals (three significant digits on its smallest value; tiny or huge values as powers of ten), a medians
    column's letter groups as superscripts, the best value of each column of `lower_is_better` in bold, a missing
    value as an en dash, a label to \\ref."""
    letters = {c[: -len(LETTERS)] for c in df.columns if str(c).endswith(LETTERS)}
    shown = [c for c in df.columns if not str(c).endswith(LETTERS)]
    method_rows = ~df[shown[0]].isin(KRUSKAL_ROWS) if len(shown) else pd.Series(dtype=bool)
    fmt = {c: _latex_format(df.loc[method_rows, c]) if method_rows.any() else None for c in shown}
    best = {}
    for c in lower_is_better:
        values = pd.to_numeric(df.loc[method_rows, c], errors="coerce") if c in df.columns else pd.Series(dtype=float)
        if values.notna().sum() > 1:
            best[c] = values.min()
    lines = [
        "% needs \\usepackage{booktabs}",
        r"\begin{table}[t]",
        r"\centering",
    ]
    if caption:
        lines.append(rf"\caption{{{_tex(caption)}}}")
    if label:
        lines.append(rf"\label{{{label}}}")
    lines += [
        rf"\begin{{tabular}}{{{'l' + 'r' * (len(shown) - 1)}}}",
        r"\toprule",
        " & ".join(_tex(header(c)) for c in shown) + r" \\",
        r"\midrule",
    ]
    for i, (_, row) in enumerate(df.iterrows()):
        if not method_rows.iloc[i] and (i == 0 or method_rows.iloc[i - 1]):
            lines.append(r"\midrule")
        cells = []
        for c in shown:
            v = row[c]
            form = fmt[c] if method_rows.iloc[i] else _test_format(str(row[shown[0]]))
            text = form(v) if form is not None and _is_number(v) else ("--" if _missing(v) else _tex(str(v)))
            if c in best and _is_number(v) and v == best[c] and method_rows.iloc[i]:
                text = rf"\textbf{{{text}}}"
            if c in letters and isinstance(row.get(c + LETTERS), str) and row[c + LETTERS]:
                text += rf"\textsuperscript{{{_tex(row[c + LETTERS])}}}"
            cells.append(text)
        lines.append(" & ".join(cells) + r" \\")
    lines += [r"\bottomrule", r"\end{tabular}", r"\end{table}"]
    return "\n".join(lines) + "\n"


def header(column: str) -> str:
    """A column's name in words, with its unit where it has one (LABELS)."""
    from slamrun.results.vocabulary import LABELS

    if column in LABELS:
        return "coverage" if column == "coverage" else LABELS[column]
    words = str(column).split(" ")  # "median ate_rmse forward": the metric's words inside
    return " ".join(LABELS.get(w, w) if w != "coverage" else w for w in words)


_TEX = {
    "\\": r"\textbackslash{}",
    "_": r"\_",
    "%": r"\%",
    "&": r"\&",
    "#": r"\#",
    "$": r"\$",
    "{": r"\{",
    "}": r"\}",
    "~": r"\textasciitilde{}",
    "^": r"\textasciicircum{}",
}


def _tex(s: str) -> str:
    """Text as LaTeX reads it literally."""
    return "".join(_TEX.get(ch, ch) for ch in s)


def _is_number(v) -> bool:
    return isinstance(v, int | float | np.integer | np.floating) and not isinstance(v, bool) and np.isfinite(v)


def _missing(v) -> bool:
    return v is None or (isinstance(v, float | np.floating) and not np.isfinite(v))


def _latex_format(column: pd.Series):
    """How a column's numbers are written: whole numbers as such; else one number of decimals for the column, three
    significant digits on its smallest magnitude, or powers of ten where that would need more than 6; None for a
    column of text."""
    values = pd.to_numeric(column, errors="coerce")
    finite = values[np.isfinite(values)]
    if finite.empty or values.isna().sum() > column.isna().sum():
        return None  # text (a method's name), or nothing to format
    if (finite == finite.round()).all() and finite.abs().max() < 1e9:
        return lambda v: f"{int(round(v))}"
    nonzero = finite[finite != 0].abs()
    smallest = nonzero.min() if len(nonzero) else 1.0
    decimals = 2 - int(np.floor(np.log10(smallest)))
    if decimals > 6 or finite.abs().max() >= 1e6:
        return _power_of_ten
    return lambda v, d=max(decimals, 0): f"{v:.{d}f}"


def _test_format(name: str):
    """How a test's row (Kruskal-Wallis chi2, df, p) writes its numbers."""
    if name.endswith(" df"):
        return lambda v: f"{int(round(v))}"
    if name.endswith(" p"):
        return lambda v: _power_of_ten(v) if 0 < v < 1e-3 else f"{v:.3f}"
    return lambda v: f"{v:.3g}"


def _power_of_ten(v: float) -> str:
    mantissa, exponent = f"{v:.2e}".split("e")
    return rf"${mantissa} \times 10^{{{int(exponent)}}}$"


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


def write_all(
    df: pd.DataFrame,
    folder: Path,
    name: str,
    caption: str = "",
    note: str = "",
    lower_is_better: tuple[str, ...] = (),
) -> None:
    """The table as CSV, Markdown and LaTeX (`caption` its LaTeX caption, `tab:NAME` its label, with the dataset's
    name in a dataset's own folder); `note`, what its values are, heads the Markdown and LaTeX files as a comment
    (the files paste as they are)."""
    folder.mkdir(parents=True, exist_ok=True)
    df.to_csv(folder / f"{name}.csv", index=False)
    what = " ".join(f"{caption}. {note}".split()) if note else ""
    (folder / f"{name}.md").write_text((f"<!-- {what.replace('--', '- -')} -->\n" if what else "") + to_markdown(df))
    dataset = folder.parent.name if folder.parent.parent.name == "datasets" else ""
    label = f"tab:{name}" + (f":{dataset}" if dataset else "")
    latex = to_latex(df, caption, label, lower_is_better)
    (folder / f"{name}.tex").write_text((f"% {what}\n" if what else "") + latex)


def _cell(v) -> str:
    if isinstance(v, float | np.floating):
        return "-" if not np.isfinite(v) else f"{v:.4g}"
    return str(v)
