"""A table's files: CSV, Markdown, LaTeX (for a paper) and HTML (for the report's page)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from slamrun.analysis.tables import KRUSKAL_ROWS, LETTERS


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
