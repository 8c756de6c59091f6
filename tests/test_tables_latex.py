"""Tables a paper can take as they are: numeric CSVs (letters in a column of their own), and LaTeX with booktabs,
headers in words with units, one number of decimals per column, the best value in bold, a missing value as an en
dash and a label; the .tex compiles with pdflatex."""

from __future__ import annotations

import os
import re
import shutil
import subprocess

import numpy as np
import pandas as pd
import pytest

from slamrun.analysis.stats import study_statistics
from slamrun.analysis.table_files import write_all
from slamrun.analysis.tables import medians_with_letters


def stats_of_three_methods():
    rng = np.random.default_rng(7)
    rows = []
    for method, centre in (("fast", 0.0291), ("slow", 0.3866), ("odd", 0.05)):
        for k in range(8):
            rows.append(
                {
                    "method": method,
                    "sequence": f"s{k}",
                    "direction": "forward",
                    "ate_rmse": centre * (1 + 0.2 * rng.random()),
                    "rpe_t_rmse": 0.01 * (1 + rng.random()),
                    "coverage": 0.2 if method == "slow" else 1.0,
                }
            )
    return study_statistics(pd.DataFrame(rows), ["ate_rmse", "rpe_t_rmse"])


@pytest.fixture
def written(tmp_path):
    st = stats_of_three_methods()
    table = medians_with_letters(st, ["ate_rmse", "rpe_t_rmse"])
    table.loc[table.method == "slow", "rpe_t_rmse"] = np.nan  # a method without a figure
    folder = tmp_path / "report" / "datasets" / "euroc" / "tables"
    write_all(table, folder, "trajectory_metrics", "ATE and RPE (euroc)", "medians", ("ate_rmse", "rpe_t_rmse"))
    return table, folder


def test_the_csv_is_numeric_with_letters_and_coverage_in_columns_of_their_own(written):
    table, folder = written
    csv = pd.read_csv(folder / "trajectory_metrics.csv")
    assert csv.ate_rmse.dtype.kind == "f" and csv["runs"].iloc[:3].tolist() == [8, 8, 8]
    assert set(csv["ate_rmse letters"].iloc[:3]) <= {"a", "b", "c", "ab", "bc", "ac"}
    assert csv.set_index("method").loc["slow", "coverage"] == pytest.approx(0.2)
    assert csv.method.iloc[-3:].tolist() == ["Kruskal-Wallis chi2", "Kruskal-Wallis df", "Kruskal-Wallis p"]


def test_the_latex_table_is_paper_ready(written):
    table, folder = written
    tex = (folder / "trajectory_metrics.tex").read_text()
    for part in (r"\toprule", r"\midrule", r"\bottomrule", r"\label{tab:trajectory_metrics:euroc}", r"\caption{"):
        assert part in tex, part
    heads = tex.replace("\\\\ ", " ")  # a header over lines (\\ between them) read as one
    assert "ATE RMSE (m)" in heads and "RPE translation RMSE (m)" in heads and "ate\\_rmse" not in tex
    body = [line for line in tex.splitlines() if line.startswith(("fast", "slow", "odd"))]
    assert len(body) == 3
    ate = [re.search(r"(\d+\.\d+)", line.split("&")[3]).group(1) for line in body]
    assert len({len(v.split(".")[1]) for v in ate}) == 1  # one number of decimals in the column
    assert len(ate[0].split(".")[1]) == 4  # three significant digits on the smallest (0.0291...)
    assert sum(r"\textbf{" in line.split("&")[3] for line in body) == 1  # the best ATE median, once
    assert all(r"\textsuperscript{" in line.split("&")[3] for line in body)  # its letters
    slow = next(line for line in body if line.startswith("slow"))
    assert slow.split("&")[4].strip().startswith("--")  # no figure: an en dash


def test_the_latex_table_compiles(written, tmp_path):
    _, folder = written
    if shutil.which("pdflatex") is None:
        if os.environ.get("CI") == "true":
            pytest.fail("pdflatex is missing: .ci/run installs texlive-latex-base and texlive-latex-recommended")
        pytest.skip(reason="no pdflatex here (apt-get install texlive-latex-base texlive-latex-recommended)")
    table = folder / "trajectory_metrics.tex"
    packages = re.findall(r"\\usepackage\{[^}]*\}", table.read_text().splitlines()[0])  # % needs \usepackage{...}
    assert "\\usepackage{booktabs" in packages[0]
    doc = tmp_path / "paper.tex"
    doc.write_text(
        "\\documentclass{article}\n" + "\n".join(packages) + "\n\\begin{document}\n"
        f"\\input{{{folder / 'trajectory_metrics.tex'}}}\nSee Table~\\ref{{tab:trajectory_metrics:euroc}}.\n"
        "\\end{document}\n"
    )
    for _ in range(2):  # the second pass resolves the reference
        out = subprocess.run(
            ["pdflatex", "-interaction=nonstopmode", "-halt-on-error", doc.name],
            cwd=tmp_path,
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert out.returncode == 0, out.stdout[-2000:]
    assert (tmp_path / "paper.pdf").stat().st_size > 1000 and "??" not in out.stdout
