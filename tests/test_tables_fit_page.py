"""A report's LaTeX tables fit a page: each .tex, in a plain one-column article (10 pt, \\linewidth 345 pt), compiles
without an overfull box over 20 pt (a wide table split into parts that repeat its name column, headers over two or
three lines, a part still too wide scaled down); headers in words with units, metric names as their labels, counts
as integers (LaTeX, Markdown, HTML)."""

from __future__ import annotations

import os
import re
import shutil
import subprocess

import numpy as np
import pandas as pd
import pytest

from slamrun.analysis.stats import study_statistics
from slamrun.analysis.table_files import to_html, to_latex, to_markdown, write_all
from slamrun.analysis.tables import medians_with_letters
from slamrun.results.catalogue import LABELS, STUDY_METRICS
from slamrun.results.vocabulary import METHOD_FAILURES

METHODS = ("reference_vo", "df_orb_slam", "study:dso", "orb_slam3_mono", "droid_slam", "dpvo_default", "ldso_loop")
SEQUENCES = (*(f"sequence_{k:02d}" for k in range(1, 8)), "V1_01_easy", "V1_02_medium", "V1_03_difficult")
SEQUENCES += ("MH_04_difficult", "MH_05_difficult", "V2_02_medium")
OVERFULL_PT = 20.0


def failures() -> pd.DataFrame:
    rng = np.random.default_rng(3)
    rows = []
    for m in METHODS:
        kinds = dict.fromkeys(METHOD_FAILURES, 0) | {"lost": int(rng.integers(0, 9)), "timeout": 2}
        failed = sum(kinds.values())
        runs = 120 + failed
        row = {"method": m, "runs": runs, "done": runs - failed, "failed (method)": failed, "infra": 1}
        row |= {"of which contended": 1, "pending": 0, "success %": round(100 * (runs - failed) / runs, 1)}
        row |= {"failure %": round(100 * failed / runs, 1), "evaluated": runs - failed, "not evaluable": 0}
        rows.append(row | kinds)
    return pd.DataFrame(rows)


def metric_tests() -> pd.DataFrame:
    rng = np.random.default_rng(4)
    rows = []
    for metric in STUDY_METRICS:
        row = {"metric": metric, "Kruskal-Wallis chi2": 130.1, "df": 6.0, "Kruskal-Wallis p": 2.29e-26}
        row |= {"Levene F": 10.12, "Levene p": 8.79e-9}
        row |= {f"Lilliefors p, {m}": float(rng.uniform(1e-4, 0.9)) for m in METHODS[:6]}
        row["no figure because"] = (
            "Lilliefors: fewer than five runs of ldso_loop after outliers were removed; Levene: the runs of "
            "droid_slam have no spread (every value the same), so the test has no statistic"
        )
        rows.append(row)
    rows[-1]["df"] = np.nan  # a metric without a test: df is a float column
    return pd.DataFrame(rows)


def resources() -> pd.DataFrame:
    rng = np.random.default_rng(5)
    rows = []
    for m in METHODS:
        rows.append(
            {
                "method": m,
                "runs": 126,
                "CPU mean %": rng.uniform(50, 300),
                "CPU peak %": rng.uniform(100, 800),
                "GPU %": rng.uniform(0, 90),
                "GPU mem MB": rng.uniform(0, 12000),
                "RAM peak MB": rng.uniform(300, 9000),
                "time (s)": rng.uniform(30, 4000),
                "FPS": rng.uniform(5, 120),
                "CPU wait %": rng.uniform(0, 40),
                "machine CPU pressure %": rng.uniform(0, 90),
                "runs with CPU wait > 15 %": float(rng.integers(0, 30)),
            }
        )
    return pd.DataFrame(rows)


def motion_bias() -> pd.DataFrame:
    rng = np.random.default_rng(6)
    rows = []
    for m in METHODS:
        rows.append(
            {
                "method": m,
                "n forward": 60,
                "n backward": 58,
                "median ate_rmse forward": rng.uniform(0.02, 2),
                "median ate_rmse backward": rng.uniform(0.02, 2),
                "p (rank-sum)": rng.uniform(0, 1),
            }
        )
    rows[0]["p (rank-sum)"] = 1.0  # a whole-number p-value keeps its column's decimals
    return pd.DataFrame(rows)


def study_medians() -> pd.DataFrame:
    """Table 3/4 layout with all six study metrics: medians, letters, coverage, Kruskal-Wallis rows."""
    rng = np.random.default_rng(7)
    rows = []
    for i, m in enumerate(METHODS):
        for k in range(12):
            row = {"method": m, "sequence": SEQUENCES[k], "direction": "forward", "coverage": 0.9 + 0.01 * i}
            rows.append(row | {metric: (1 + i) * (1 + rng.random()) * 0.1 for metric in STUDY_METRICS})
    return medians_with_letters(study_statistics(pd.DataFrame(rows), list(STUDY_METRICS)), list(STUDY_METRICS))


def per_sequence() -> pd.DataFrame:
    rng = np.random.default_rng(8)
    table = pd.DataFrame(rng.uniform(0.01, 3, (len(METHODS), len(SEQUENCES))), columns=list(SEQUENCES))
    table.iloc[2, 4] = np.nan  # no evaluated run there
    table.insert(0, "method", list(METHODS))
    return table


def pairwise() -> pd.DataFrame:
    rng = np.random.default_rng(9)
    rows = []
    for metric in STUDY_METRICS[:2]:
        for a in METHODS[:4]:
            for b in METHODS[:4]:
                if a < b:
                    p = float(rng.uniform(0, 0.2))
                    rows.append({"metric": metric, "method a": a, "method b": b, "p (holm)": min(1.0, 3 * p)})
                    rows[-1] |= {"p (unadjusted)": p, "different at 0.05": "yes" if 3 * p < 0.05 else "no"}
    return pd.DataFrame(rows)


TABLES = {
    "failures": failures,
    "tests": metric_tests,
    "table2_resources": resources,
    "motion_bias": motion_bias,
    "table3_drift": study_medians,
    "e_align_per_sequence": per_sequence,
    "pairwise": pairwise,
}


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    out = tmp_path_factory.mktemp("report") / "tables"
    for name, make in TABLES.items():
        lower = tuple(c for c in STUDY_METRICS) if name == "table3_drift" else ()
        write_all(make(), out, name, f"The {name} table", "what its values are", lower)
    return out


def needs_pdflatex() -> None:
    if shutil.which("pdflatex") is None:
        if os.environ.get("CI") == "true":
            pytest.fail("pdflatex is missing: .ci/run installs texlive-latex-base and texlive-latex-recommended")
        pytest.skip(reason="no pdflatex here (apt-get install texlive-latex-base texlive-latex-recommended)")


def overfull_pt(tex_file, tmp_path) -> list[float]:
    """Compile the table alone in a plain one-column article with the packages its first line names; the widths
    (pt) of its overfull boxes."""
    first = tex_file.read_text().splitlines()[0]
    assert first.startswith("% needs \\usepackage{"), first
    packages = re.findall(r"\\usepackage\{[^}]*\}", first)
    doc = tmp_path / "paper.tex"
    doc.write_text(
        "\\documentclass{article}\n" + "\n".join(packages) + "\n\\begin{document}\n"
        f"\\input{{{tex_file}}}\n\\clearpage\n\\end{{document}}\n"
    )
    out = subprocess.run(
        ["pdflatex", "-interaction=nonstopmode", "-halt-on-error", doc.name],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode == 0, out.stdout[-2000:]
    log = (tmp_path / "paper.log").read_text(errors="replace")
    return [float(x) for x in re.findall(r"Overfull \\hbox \(([\d.]+)pt too wide\)", log)]


@pytest.mark.parametrize("name", TABLES)
def test_each_table_fits_a_one_column_page(folder, tmp_path, name):
    needs_pdflatex()
    widths = overfull_pt(folder / f"{name}.tex", tmp_path)
    assert max(widths, default=0.0) <= OVERFULL_PT, f"{name}: overfull by {max(widths)} pt"


def test_a_wide_table_is_split_into_parts_that_repeat_its_name_column(folder):
    tex = (folder / "e_align_per_sequence.tex").read_text()
    parts = tex.split("\\begin{tabular}{")[1:]
    assert len(parts) >= 2 and tex.count("\\caption{") == 1 and tex.count("\\begin{table}") == 1
    for part in parts:
        assert part.count("\\toprule") == 1 and part.count("\\bottomrule") == 1
        head = part.split("\\toprule", 1)[1].split("\\midrule", 1)[0]
        assert head.strip().startswith("method")
        rows = part.split("\\midrule", 1)[1].split("\\bottomrule")[0].strip().splitlines()
        assert [r.split(" & ")[0] for r in rows] == [m.replace("_", "\\_") for m in METHODS]
    every = "".join(parts)
    for s in SEQUENCES:  # every sequence once, its header maybe over lines
        assert every.replace("\\\\ ", "").count(s.replace("_", "\\_")) == 1, s
    assert "--" in every  # the missing median


def test_the_split_keeps_the_medians_layout(folder):
    tex = (folder / "table3_drift.tex").read_text()
    for part in tex.split("\\begin{tabular}{")[1:]:
        body = part.split("\\midrule", 1)[1]
        methods, tests = body.split("\\midrule", 1)  # the Kruskal-Wallis rows after a rule of their own
        assert len(methods.strip().splitlines()) == len(METHODS)
        assert [r.split(" & ")[0] for r in tests.strip().splitlines()[:3]] == [
            "Kruskal-Wallis chi2",
            "Kruskal-Wallis df",
            "Kruskal-Wallis p",
        ]
        assert "\\textsuperscript{" in methods and "\\textbf{" in methods
    assert "translation drift e\\_t (GT units)" in tex.replace("\\\\ ", " ").replace("\\end{tabular}", "")


def test_headers_have_units_and_labels_and_no_raw_names(folder):
    failures = (folder / "failures.tex").read_text()
    assert "not\\_initialized" not in failures and "bad timestamps" in failures.replace("\\\\ ", " ")
    assert "success (\\%)" in failures.replace("\\\\ ", " ")
    resources = (folder / "table2_resources.tex").read_text().replace("\\\\ ", " ")
    for unit in ("CPU mean (\\%)", "GPU mem (MB)", "RAM peak (MB)", "time (s)", "\\textgreater{}"):
        assert unit in resources, unit
    tests = (folder / "tests.tex").read_text()
    assert "e\\_s\\_sym" not in tests and "scale drift e\\_s' (factor)" in tests.replace("\\\\ ", " ")
    md = (folder / "tests.md").read_text()
    assert "| scale drift e_s' (factor) |" in md and "| e_s_sym |" not in md
    assert pd.read_csv(folder / "tests.csv").metric.tolist() == list(STUDY_METRICS)  # for machines: raw names
    bias = (folder / "motion_bias.tex").read_text().replace("\\\\ ", " ")
    assert "median " + LABELS["ate_rmse"] in bias


def test_counts_are_integers_everywhere(folder):
    res = resources()
    counts = [str(int(v)) for v in res["runs with CPU wait > 15 %"]]  # a float column of whole numbers
    md = [line.strip(" |").split(" | ")[-1] for line in to_markdown(res).splitlines()[2:]]
    html = re.findall(r"<td>([^<]*)</td></tr>", to_html(res))
    tex = (folder / "table2_resources.tex").read_text().splitlines()
    last = [next(r for r in reversed(tex) if r.startswith(m.replace("_", "\\_"))) for m in res.method]
    assert md == counts and html == counts and [r.split(" & ")[-1].removesuffix(" \\\\") for r in last] == counts
    tests = metric_tests()  # df: a count with a NaN
    assert "| 6 |" in to_markdown(tests) and "<td>6</td>" in to_html(tests)
    assert " & 6 & " in (folder / "tests.tex").read_text() and "6.0" not in (folder / "tests.tex").read_text()
    medians = study_medians()
    assert medians["runs"].dtype.kind == "f"  # NaN in its Kruskal-Wallis rows
    md = to_markdown(medians)
    assert f"| {int(medians.runs.iloc[0])} |" in md and not re.search(r"\| \d+\.0 \|", md)
    bias = (folder / "motion_bias.tex").read_text().splitlines()
    p_one = next(r for r in reversed(bias) if r.startswith("reference\\_vo"))
    assert re.search(r"& 1\.0{3,} \\\\$", p_one)  # p = 1 at its column's decimals, in the part with the p-values
    assert re.search(r"\| 1\.000 \|", to_markdown(motion_bias()))


def test_a_narrow_table_stays_as_it_is_and_a_wide_part_is_only_scaled_down():
    narrow = to_latex(motion_bias().iloc[:, :3], "Runs per direction", "tab:n")
    assert narrow.splitlines()[0] == "% needs \\usepackage{booktabs}"
    assert narrow.count("\\begin{tabular}{") == 1 and "\\resizebox" not in narrow
    wide = to_latex(pairwise(), "Pairs", "tab:p")  # its three name columns leave no room to split: one part
    assert wide.splitlines()[0] == "% needs \\usepackage{booktabs,graphicx}" and wide.count("\\begin{tabular}{") == 1
    assert "\\ifdim\\wd0>\\linewidth\\resizebox{\\linewidth}{!}{\\usebox0}\\else\\usebox0\\fi" in wide
