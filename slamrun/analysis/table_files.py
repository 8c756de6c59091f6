"""A table's files: CSV, Markdown, LaTeX (for a paper) and HTML (for the report's page)."""

from __future__ import annotations

import itertools
import re
from pathlib import Path

import numpy as np
import pandas as pd

from slamrun.analysis.tables import KRUSKAL_ROWS, LETTERS
from slamrun.results.catalogue import COVERAGE, LABELS
from slamrun.results.vocabulary import FAILURES

ROOM_PT = 345.0  # \linewidth of a one-column article at 10 pt: the width a LaTeX table's parts are fitted to
_SEP_PT = 12.0  # a column's two \tabcolsep
_WRAP_PT = 150.0  # a text cell wider than this is set as a paragraph this wide
_GUARD = 0.9  # a part estimated wider than this share of ROOM_PT is measured when typeset, and scaled down if wider
# (the estimate is within 1 % in Computer Modern; a font or size a tenth wider still fits)
_HEAD_LINES = 3  # the most lines a header wraps over


def to_markdown(df: pd.DataFrame) -> str:
    """The table in Markdown: headers and metric names in words with their units, numbers as in LaTeX (counts as
    integers, one number of decimals per column)."""
    cells = _plain_cells(df, labels=True)
    head = "| " + " | ".join(header(c) for c in df.columns) + " |\n|" + "---|" * len(df.columns) + "\n"
    return head + "".join("| " + " | ".join(v.replace("|", "\\|") for v in r) + " |\n" for r in cells)


def to_latex(
    df: pd.DataFrame, caption: str = "", label: str = "", lower_is_better: tuple[str, ...] = (), room: float = ROOM_PT
) -> str:
    """The table for a paper (booktabs): headers in words with their units, each numeric column at one number of
    decimals (three significant digits on its smallest value; tiny or huge values as powers of ten), a medians
    column's letter groups as superscripts, the best value of each column of `lower_is_better` in bold, a missing
    value as an en dash, a label to \\ref. A table wider than `room` (pt) has its headers over up to three lines
    and, if still wider, is split into parts stacked in its float, each repeating the leading text columns (the
    names); a part near `room` is measured when typeset and scaled down to \\linewidth where wider. The first line
    names the packages it needs."""
    shown = [j for j, c in enumerate(df.columns) if not str(c).endswith(LETTERS)]
    body, numeric, methods = _latex_cells(df, shown, lower_is_better)
    keys = next((k for k, j in enumerate(shown) if pd.api.types.is_numeric_dtype(df.dtypes.iloc[j])), len(shown))
    body = [[_paragraph(t) for t in row] for row in body]
    heads, widths, parts = _layout([header(df.columns[j]) for j in shown], body, max(keys, 1), room)
    guarded = [sum(widths[j] for j in part) > _GUARD * room for part in parts]
    lines = [
        "% needs \\usepackage{booktabs" + (",graphicx" if any(guarded) else "") + "}",
        r"\begin{table}[t]",
        r"\centering",
    ]
    if caption:
        lines.append(rf"\caption{{{_tex(caption)}}}")
    if label:
        lines.append(rf"\label{{{label}}}")
    for k, (part, guard) in enumerate(zip(parts, guarded, strict=True)):
        if k:
            lines.append(r"\par\medskip")
        tab = [
            rf"\begin{{tabular}}{{{''.join('r' if numeric[j] else 'l' for j in part) or 'l'}}}",
            r"\toprule",
            " & ".join(_head_cell(heads[j], "c" if numeric[j] else "l") for j in part) + r" \\",
            r"\midrule",
        ]
        for i, cells in enumerate(body):
            if i and methods[i] != methods[i - 1]:
                tab.append(r"\midrule")  # the Kruskal-Wallis rows after their methods
            tab.append(" & ".join(cells[j] for j in part) + r" \\")
        tab += [r"\bottomrule", r"\end{tabular}"]
        if guard:  # measured as typeset: scaled down where wider than the line, never enlarged
            tab = [r"\sbox0{%", *tab[:-1], tab[-1] + "}%"]
            tab.append(r"\ifdim\wd0>\linewidth\resizebox{\linewidth}{!}{\usebox0}\else\usebox0\fi")
        lines += tab
    lines.append(r"\end{table}")
    return "\n".join(lines) + "\n"


def _latex_cells(
    df: pd.DataFrame, shown: list[int], lower_is_better: tuple[str, ...]
) -> tuple[list[list[str]], list[bool], list[bool]]:
    """The LaTeX of the cells of the `shown` columns (positions), whether each column is numeric, and whether each
    row is a method's (else a Kruskal-Wallis row)."""
    letters = {c[: -len(LETTERS)] for c in df.columns if str(c).endswith(LETTERS)}
    tests = _test_rows(df)
    methods = [t == "" for t in tests]
    fmt = {j: _latex_format(df.iloc[methods, j]) if any(methods) else None for j in shown}
    whole = {j: _whole(df.iloc[methods, j]) for j in shown}
    best = {}
    for c in lower_is_better:
        values = pd.to_numeric(df.loc[methods, c], errors="coerce") if c in df.columns else pd.Series(dtype=float)
        if values.notna().sum() > 1:
            best[c] = values.min()
    body = []
    for i, row in enumerate(df.itertuples(index=False)):
        cells = []
        for j in shown:
            c, v = df.columns[j], row[j]
            form = fmt[j] if methods[i] else _test_format(tests[i])
            if _missing(v):
                text = "--"
            elif _is_number(v):
                text = form(v) if form is not None else _plain(v, whole[j])
            else:
                text = _tex(LABELS.get(v, v) if c == "metric" and isinstance(v, str) else str(v))
            if c in best and _is_number(v) and v == best[c] and methods[i]:
                text = rf"\textbf{{{text}}}"
            mark = row[df.columns.get_loc(c + LETTERS)] if c in letters else None
            if isinstance(mark, str) and mark:
                text += rf"\textsuperscript{{{_tex(mark)}}}"
            cells.append(text)
        body.append(cells)
    return body, [fmt[j] is not None for j in shown], methods


def _paragraph(text: str) -> str:
    """A cell wider than _WRAP_PT as a paragraph that wide."""
    return text if _width(text) <= _WRAP_PT else rf"\parbox[t]{{{_WRAP_PT:g}pt}}{{\raggedright {text}}}"


def _layout(
    heads: list[str], body: list[list[str]], keys: int, room: float
) -> tuple[list[list[str]], list[float], list[list[int]]]:
    """Each column's header lines, its width (pt, with its padding) and the parts of the table (the columns of each):
    headers on as few lines as let the whole table fit `room` (up to three: each on the lines that narrow its
    column most); the columns after the `keys` first in consecutive groups that each fit beside those (one part
    where they leave no room for the widest)."""
    cells = [max((_width(row[j]) for row in body), default=0.0) for j in range(len(heads))]
    options = [_head_options(h) for h in heads]
    for most in range(1, _HEAD_LINES + 1):
        chosen = [_narrowest(o[:most], w) for o, w in zip(options, cells, strict=True)]
        widths = [max(w, _lines_width(h)) + _SEP_PT for w, h in zip(cells, chosen, strict=True)]
        if sum(widths) <= room:
            break
    if len(heads) <= keys or sum(widths[:keys]) + max(widths[keys:]) > room:
        return chosen, widths, [list(range(len(heads)))]  # no room to repeat the names: one part, scaled down
    groups = _groups(widths[keys:], room - sum(widths[:keys]))
    return chosen, widths, [[*range(keys), *(keys + i for i in g)] for g in groups]


def _groups(widths: list[float], room: float) -> list[list[int]]:
    """Consecutive groups of columns of these widths: as few as fit `room` each (a wider column alone), and of
    widths as even as can be."""

    def pack(cap: float) -> list[list[int]]:
        groups: list[list[int]] = [[]]
        used = 0.0
        for i, w in enumerate(widths):
            if groups[-1] and used + w > cap:
                groups.append([])
                used = 0.0
            groups[-1].append(i)
            used += w
        return groups

    n = len(pack(room))
    cap = max(max(widths), sum(widths) / n)
    while len(groups := pack(cap)) > n:  # greedy packing takes no more groups as `cap` grows: at `room`, n
        cap += 1.0
    return groups


def _head_options(text: str) -> list[list[str]]:
    """A header's text on one, two and three lines, its words spread as evenly as they go (a one-word header, such
    as a sequence's name, on two at most, broken after an underscore)."""
    words, glue, most = text.split(" "), " ", _HEAD_LINES
    if len(words) == 1:
        words, glue, most = re.findall(r"[^_]*_+|[^_]+", text) or [text], "", 2
    options = []
    for k in range(1, min(most, len(words)) + 1):
        splits = [(0, *cuts, len(words)) for cuts in itertools.combinations(range(1, len(words)), k - 1)]
        lines = [[glue.join(words[a:b]) for a, b in itertools.pairwise(s)] for s in splits]
        options.append(min(lines, key=_lines_width))
    return options


def _narrowest(options: list[list[str]], cells: float) -> list[str]:
    """The fewest lines that make a column (its cells `cells` pt wide) about as narrow as its header can (within a
    quarter: another line only where it saves more)."""
    widths = [max(cells, _lines_width(o)) for o in options]
    return next(o for o, w in zip(options, widths, strict=True) if w <= 1.25 * min(widths))


def _lines_width(lines: list[str]) -> float:
    return max(_width(_tex(line)) for line in lines)


def _head_cell(lines: list[str], align: str) -> str:
    """A header cell: its text, or its lines stacked (bottom lines level)."""
    if len(lines) == 1:
        return _tex(lines[0])
    return rf"\begin{{tabular}}[b]{{@{{}}{align}@{{}}}}" + "\\\\ ".join(map(_tex, lines)) + r"\end{tabular}"


# Computer Modern Roman 10 pt: the widths (pt) of the printable ASCII characters, space to tilde (OT1)
_CM10 = dict(
    zip(
        map(chr, range(32, 127)),
        map(
            float,
            """2.78 2.78 5 8.33 5 8.33 7.78 2.78 3.89 3.89 5 7.78 2.78 3.33 2.78 5 5 5 5 5 5 5 5 5 5 5 2.78 2.78 2.78
            7.78 4.72 4.72 7.78 7.5 7.08 7.22 7.64 6.81 6.53 7.85 7.5 3.61 5.14 7.78 6.25 9.17 7.5 7.78 6.81 7.78 7.36
            5.56 7.22 7.5 7.5 10.28 7.5 7.5 6.11 2.78 5 2.78 5 2.78 2.78 5 5.56 4.44 5.56 4.44 3.06 5 5.56 2.78 3.06
            5.28 2.78 8.33 5.56 5 5.56 5.28 3.92 3.94 3.89 5.56 5.28 7.22 5.28 5.28 4.44 5 10 5 5""".split(),
        ),
        strict=True,
    )
)
_ESCAPED = {"_": 3.6, "%": 8.33, "&": 7.78, "#": 8.33, "$": 5.0, "{": 5.0, "}": 5.0}
_PIECE = re.compile(
    r"\\(?P<cmd>textbf|textsuperscript|parbox\[t\]\{(?P<box>[\d.]+)pt\})\{(?P<arg>(?:[^{}]|\{[^{}]*\})*)\}"
    r"|\$(?P<math>[^$]*)\$|\\(?P<esc>[_%&#${}])|\\[a-z]+\{\}|--|."
)


def _width(tex: str) -> float:
    """The width (pt) of a cell's LaTeX in Computer Modern 10 pt, estimated from its characters' widths: bold 15 %
    wider, superscripts at 84 %, a power of ten as $m \\times 10^{e}$ sets it."""
    total = 0.0
    for m in _PIECE.finditer(tex):
        if m["box"]:
            total += float(m["box"])
        elif m["cmd"]:
            total += (1.15 if m["cmd"] == "textbf" else 0.84) * _width(m["arg"])
        elif m["math"] is not None:
            mantissa, _, exponent = m["math"].partition(r" \times 10^")
            total += _width(mantissa) + (
                22.2 + 0.84 * _width(exponent.strip("{}").replace("-", "+")) if exponent else 0
            )
        elif m["esc"]:
            total += _ESCAPED[m["esc"]]
        else:
            total += _CM10.get(m[0], 5.0)  # an en dash, a symbol (\textless{}), a letter beyond ASCII: about 5
    return total


def header(column: str) -> str:
    """A column's name in words, with its unit where it has one: a metric's label (LABELS), also among words
    ("median ate_rmse forward"); a failure kind's words; a closing unit in parentheses ("CPU mean (%)")."""
    name = str(column)
    if name == COVERAGE:
        return name
    if name in LABELS:
        return LABELS[name]
    if name in FAILURES:
        return name.replace("_", " ")
    words = [LABELS.get(w, w) if w != COVERAGE else w for w in name.split(" ")]
    if len(words) > 1 and words[-1] in _UNITS and not words[-2].replace(".", "").isdigit():  # not "> 15 %"
        words[-1] = f"({words[-1]})"
    return " ".join(words)


_UNITS = ("%", "MB", "GB", "s", "ms")


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
    "<": r"\textless{}",
    ">": r"\textgreater{}",
    "|": r"\textbar{}",
}


def _tex(s: str) -> str:
    """Text as LaTeX reads it literally."""
    return "".join(_TEX.get(ch, ch) for ch in s)


def _is_number(v) -> bool:
    return isinstance(v, int | float | np.integer | np.floating) and not isinstance(v, bool) and np.isfinite(v)


def _missing(v) -> bool:
    return v is None or (isinstance(v, float | np.floating) and not np.isfinite(v))


def _whole(column: pd.Series) -> bool:
    """A column of counts: it has numbers, all whole (2.0 where a NaN made pandas store floats)."""
    numbers = [float(v) for v in column if _is_number(v)]
    return bool(numbers) and all(v.is_integer() and abs(v) < 1e15 for v in numbers)


def _test_rows(df: pd.DataFrame) -> list[str]:
    """Each row's Kruskal-Wallis row name (in whichever column: a level's test rows follow its methods), else ''."""
    names = set(KRUSKAL_ROWS)
    return [next((v for v in row if isinstance(v, str) and v in names), "") for row in df.itertuples(index=False)]


def _plain(v, whole: bool) -> str:
    """A value as text: a count as an integer, another number at four significant digits (a whole one with its
    zeros, 1.000: never read as a count), a missing value as '-'."""
    if _missing(v):
        return "-"
    if not _is_number(v):
        return str(v)
    if whole:
        return str(int(round(v)))
    return _significant(v, 4)


def _significant(v: float, digits: int) -> str:
    """A number at `digits` significant digits; a whole one with its zeros (74.0, 1.000: never read as a count)."""
    return f"{v:#.{digits}g}".rstrip(".") if float(v).is_integer() else f"{v:.{digits}g}"


def _plain_cells(df: pd.DataFrame, labels: bool) -> list[list[str]]:
    """The table's cells as text (Markdown, HTML): a numeric column's numbers as in LaTeX (counts as integers, one
    number of decimals per column, judged over the methods' rows), a Kruskal-Wallis row's at four significant digits
    (its df as an integer), a missing value as '-'; with `labels`, a metric's name in a `metric` column as its
    label."""
    tests = _test_rows(df)
    methods = [t == "" for t in tests]
    fmt = [_latex_format(df.iloc[methods, j], plain=True) if any(methods) else None for j in range(df.shape[1])]
    whole = [_whole(df.iloc[methods, j]) for j in range(df.shape[1])]
    out = []
    for t, row in zip(tests, df.itertuples(index=False), strict=True):
        cells = []
        for j, (c, v) in enumerate(zip(df.columns, row, strict=True)):
            if labels and c == "metric" and isinstance(v, str) and v in LABELS:
                cells.append(LABELS[v])
            elif t == "" and fmt[j] is not None and _is_number(v):
                cells.append(fmt[j](v))
            else:
                cells.append(_plain(v, whole[j] if t == "" else t.endswith(" df")))
        out.append(cells)
    return out


def _latex_format(column: pd.Series, plain: bool = False):
    """How a column's numbers are written: whole numbers as such; else one number of decimals for the column, three
    significant digits on its smallest magnitude, or powers of ten where that would need more than 6 (`plain`: as
    2.29e-26, not in LaTeX); None for a column of text."""
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
        return (lambda v: f"{v:.2e}") if plain else _power_of_ten
    return lambda v, d=max(decimals, 0): f"{v:.{d}f}"


def _test_format(name: str):
    """How a test's row (Kruskal-Wallis chi2, df, p) writes its numbers."""
    if name.endswith(" df"):
        return lambda v: f"{int(round(v))}"
    if name.endswith(" p"):
        return lambda v: _power_of_ten(v) if 0 < v < 1e-3 else f"{v:.3f}"
    return lambda v: _significant(v, 3)


def _power_of_ten(v: float) -> str:
    mantissa, exponent = f"{v:.2e}".split("e")
    return rf"${mantissa} \times 10^{{{int(exponent)}}}$"


def to_html(df: pd.DataFrame) -> str:
    """The table as HTML: numbers as in LaTeX (counts as integers, one number of decimals per column), a missing
    value as '-'."""
    import html

    # a long column name may break after an underscore: the table keeps to the page's width
    head = "".join(f"<th>{html.escape(str(c)).replace('_', '_<wbr>')}</th>" for c in df.columns)
    body = "".join(
        "<tr>" + "".join(f"<td>{html.escape(v)}</td>" for v in row) + "</tr>" for row in _plain_cells(df, False)
    )
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def write_all(
    df: pd.DataFrame,
    folder: Path,
    name: str,
    caption: str = "",
    note: str = "",
    lower_is_better: tuple[str, ...] = (),
    csv: pd.DataFrame | None = None,
) -> None:
    """The table as CSV, Markdown and LaTeX (`caption` its LaTeX caption, `tab:NAME` its label, with the dataset's
    name in a dataset's own folder); `note`, what its values are, heads the Markdown file as a comment, and the
    LaTeX file after its first line, the packages it needs (the files paste as they are). `csv`: the CSV's own
    table where it differs (names without marks, the marks in a column of their own: machines read it)."""
    folder.mkdir(parents=True, exist_ok=True)
    (df if csv is None else csv).to_csv(folder / f"{name}.csv", index=False)
    what = " ".join(f"{caption}. {note}".split()) if note else ""
    (folder / f"{name}.md").write_text((f"<!-- {what.replace('--', '- -')} -->\n" if what else "") + to_markdown(df))
    dataset = folder.parent.name if folder.parent.parent.name == "datasets" else ""
    label = f"tab:{name}" + (f":{dataset}" if dataset else "")
    needs, latex = to_latex(df, caption, label, lower_is_better).split("\n", 1)
    (folder / f"{name}.tex").write_text(needs + "\n" + (f"% {what}\n" if what else "") + latex)
