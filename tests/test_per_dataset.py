"""Statistics within each dataset: a real campaign of a synthetic EuRoC and a synthetic KITTI sequence, two methods
(the fake method at two noise levels), forward and backward, ATE and RPE. `stats --json` has one block per dataset
equal to the statistics of that dataset's rows alone; the report's tables and the terminal summary are per dataset;
nothing in metres is pooled; every JSON is RFC 8259."""

from __future__ import annotations

import contextlib
import io
import json
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from slamrun.cli import main
from slamrun.datasets.make_synthetic import generate
from tests.conftest import fake_method, write_spec

SLAMRUN = [sys.executable, "-m", "slamrun.cli"]
DATASETS = ("euroc", "kitti")
TRIALS = 3


def strict_json(text: str):
    """Parses as a strict RFC 8259 parser does: bare NaN / Infinity refused."""

    def refuse(name: str):
        raise ValueError(f"not JSON: {name}")

    return json.loads(text, parse_constant=refuse)


def slamrun(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([*SLAMRUN, *map(str, args)], capture_output=True, text=True, timeout=300, cwd=cwd)


@dataclass(frozen=True)
class Campaign:
    results: Path
    stdout: str
    df: pd.DataFrame  # results.csv, text columns as text


@pytest.fixture(scope="session")
def two_datasets(tmp_path_factory) -> Campaign:
    """A campaign over two datasets (EuRoC's room, KITTI's outdoor drive): `slamrun campaign` in a process."""
    root = tmp_path_factory.mktemp("two_datasets")
    generate(root / "euroc" / "V1_synth", frames=40, seed=3, size=(160, 120), layout="euroc")
    generate(
        root / "kitti" / "sequences" / "00", frames=40, seed=5, size=(160, 120), layout="kitti", scene_kind="outdoor"
    )
    datasets = [
        {"name": "euroc", "path": str(root / "euroc"), "sequences": ["V1_synth"], "layout": "euroc"},
        {"name": "kitti", "path": str(root / "kitti" / "sequences"), "sequences": ["00"], "layout": "kitti"},
    ]
    methods = [
        fake_method(label="steady", extra=["--noise", "0.002", "--vary"]),
        fake_method(label="shaky", extra=["--noise", "0.02", "--vary"]),
    ]
    spec = write_spec(root, root, methods, datasets=datasets, trials=TRIALS, report=True)
    p = slamrun("campaign", spec)
    assert p.returncode == 0, p.stdout + p.stderr
    results = root / "results"
    df = pd.read_csv(results / "results.csv", dtype={"sequence": str, "dataset": str})
    assert len(df) == 2 * 2 * 2 * TRIALS and df.status.eq("done").all() and df.ate_rmse.notna().all()
    return Campaign(results, p.stdout, df)


def stats_out(*args) -> str:
    """`slamrun stats ARGS`' output, run in this process (the command line's own path, without a process's start)."""
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(["stats", *map(str, args)]) == 0
    return buf.getvalue()


def stats_json(*args) -> dict:
    return strict_json(stats_out(*args, "--json"))


def alone(campaign: Campaign, name: str, folder: Path) -> Path:
    """That dataset's rows alone, as a one-dataset campaign's results.csv."""
    folder.mkdir(parents=True, exist_ok=True)
    campaign.df[campaign.df.dataset == name].to_csv(folder / "results.csv", index=False)
    return folder / "results.csv"


def test_stats_json_has_one_block_per_dataset_equal_to_its_rows_alone(two_datasets, tmp_path):
    p = slamrun("stats", two_datasets.results, "--json")  # a script's view: the process's output, strict JSON
    assert p.returncode == 0, p.stderr
    out = strict_json(p.stdout)
    assert out == stats_json(two_datasets.results)
    assert set(out["datasets"]) == set(DATASETS)
    df = two_datasets.df
    for name in DATASETS:
        block = out["datasets"][name]
        own = stats_json(alone(two_datasets, name, tmp_path / name))
        assert own["datasets"] == {name: block}  # one key for a one-dataset campaign, the same figures
        assert set(block["metrics"]) == {"ate_rmse", "rpe_t_rmse", "rpe_r_rmse"}  # the metrics its runs have
        assert len(block["mahalanobis"]) == 2 * 2 * TRIALS  # its runs only
        rows = df[df.dataset == name]
        for method in ("steady", "shaky"):  # medians of that dataset's runs, not of both
            ate = rows.loc[rows.method == method, "ate_rmse"]
            assert block["metrics"]["ate_rmse"]["medians"][method] == pytest.approx(np.median(ate), rel=1e-12)
        assert block["metrics"]["ate_rmse"]["letters"]["steady"] != block["metrics"]["ate_rmse"]["letters"]["shaky"]
    # the pooled view pools only what is sound and says so
    pooled = out["pooled"]
    assert pooled["datasets"] == list(DATASETS) and "pooled" in pooled["note"]
    assert pooled["ranked_by"] == {"euroc": "ate_rmse", "kitti": "ate_rmse"}
    assert pooled["methods"]["steady"]["mean_rank"] == 1.0 and pooled["methods"]["shaky"]["mean_rank"] == 2.0
    assert pooled["methods"]["steady"]["runs"] == 2 * 2 * TRIALS and pooled["methods"]["steady"]["success_pct"] == 100
    assert not any("median" in k for k in pooled["methods"]["steady"])


def test_dataset_keeps_one_and_an_unknown_name_lists_the_known(two_datasets):
    out = stats_json(two_datasets.results, "--dataset", "kitti")
    assert list(out["datasets"]) == ["kitti"]
    assert out["datasets"]["kitti"] == stats_json(two_datasets.results)["datasets"]["kitti"]
    p = slamrun("stats", two_datasets.results, "--dataset", "tum")
    assert p.returncode == 1 and "Traceback" not in p.stderr
    assert p.stderr.strip().splitlines() == [
        f"slamrun: error: {two_datasets.results}: no dataset 'tum' in its runs; known: euroc, kitti"
    ]


def test_stats_text_prints_every_test_per_dataset(two_datasets):
    text = stats_out(two_datasets.results)
    out = stats_json(two_datasets.results)
    for name in DATASETS:
        section = text.split(f"dataset {name}:")[1].split("dataset ")[0]
        for test in ("Lilliefors", "Levene", "Kruskal-Wallis", "Wilcoxon"):
            assert section.count(test) == 3, (name, test)  # one per metric
        m = out["datasets"][name]["metrics"]["ate_rmse"]
        assert f"Levene (median-centred): F {m['levene_F']:.4g}, p {m['levene_p']:.3g}" in section
        assert f"steady {m['lilliefors_p']['steady']:.3g}" in section
    assert "all datasets, pooled (euroc, kitti)" in text


def test_stats_help_says_what_the_default_metrics_are():
    p = slamrun("stats", "--help")
    assert "the study's six" not in " ".join(p.stdout.split())
    assert "per dataset, the metrics its runs have" in " ".join(p.stdout.split())


def test_the_report_has_one_section_and_folder_per_dataset(two_datasets):
    report = two_datasets.results / "report"
    df = two_datasets.df
    out = stats_json(two_datasets.results)
    html = (report / "index.html").read_text()
    for name in DATASETS:
        assert f"<h2>Dataset {name}</h2>" in html
        folder = report / "datasets" / name
        assert strict_json((folder / "statistics.json").read_text()) == out["datasets"][name]
        rows = df[df.dataset == name]
        table = pd.read_csv(folder / "tables" / "trajectory_metrics.csv").set_index("method")
        for method in ("steady", "shaky"):
            ate = np.median(rows.loc[rows.method == method, "ate_rmse"])
            assert table.loc[method, "ate_rmse"] == pytest.approx(ate, rel=1e-12)
            assert table.loc[method, "ate_rmse letters"] in ("a", "b", "ab")
        bias = pd.read_csv(folder / "tables" / "motion_bias.csv").set_index("method")
        for direction in ("forward", "backward"):
            ate = rows.loc[(rows.method == "steady") & (rows.direction == direction), "ate_rmse"]
            assert bias.loc["steady", f"median ate_rmse {direction}"] == pytest.approx(np.median(ate), rel=1e-9)
        assert (folder / "statistics_forward.json").is_file() and (folder / "figures" / "box_ate_rmse.png").is_file()
        assert (folder / "tables" / "failures.csv").is_file()
        assert (
            "\\caption{Forward vs backward ate\\_rmse (" + name + ")}"
            in (folder / "tables" / "motion_bias.tex").read_text()
        )
    # nothing in metres at the top: only the pooled counts and ranks, labelled as pooled
    assert sorted(p.name for p in (report / "tables").glob("*.csv")) == [
        "failures.csv",
        "pooled_ranks.csv",
        "sequence_ranks.csv",
    ]
    assert not (report / "statistics.json").exists() and not (report / "figures").exists()
    assert "Runs and failures per method, all datasets (pooled)" in html
    failures = pd.read_csv(report / "tables" / "failures.csv").set_index("method")
    assert failures.loc["steady", "runs"] == 2 * 2 * TRIALS
    for path in report.rglob("*.json"):
        strict_json(path.read_text())


def terminal_rows(stdout: str, title: str) -> dict[str, list[str]]:
    """The rows of the rich table titled `title` in a campaign's output: method -> cells."""
    lines = stdout.splitlines()
    start = next(i for i, line in enumerate(lines) if line.strip() == title)
    rows = {"header": [c.strip() for c in lines[start + 2].split("┃")[1:-1]]}
    for line in lines[start + 3 :]:
        if line.startswith("└"):
            break
        cells = [c.strip() for c in line.split("│")[1:-1]]
        if cells and cells[0] in ("steady", "shaky"):
            rows[cells[0]] = cells
    return rows


def test_the_terminal_summary_is_per_dataset(two_datasets):
    df = two_datasets.df
    for name in DATASETS:
        table = terminal_rows(two_datasets.stdout, f"t: per method, dataset {name}")
        header = table["header"]
        assert "med ate_rmse" in header
        rows = df[df.dataset == name]
        for method in ("steady", "shaky"):
            cells = dict(zip(header, table[method], strict=True))
            ate = np.median(rows.loc[rows.method == method, "ate_rmse"])
            assert cells["med ate_rmse"] == f"{ate:.4g}" and cells["runs"] == str(2 * TRIALS)
    pooled = terminal_rows(two_datasets.stdout, "t: per method, all datasets (pooled)")
    assert not any("med" in c for c in pooled["header"])  # no median in metres over both datasets
    cells = dict(zip(pooled["header"], pooled["steady"], strict=True))
    assert cells["runs"] == str(2 * 2 * TRIALS) and cells["mean rank"] == "1"


def small_table() -> pd.DataFrame:
    """Two datasets by hand: in `a` x wins s1, z s2 (x and y tie); in `b` x alone has a value, y failed (lost), z's
    only run failed for infrastructure reasons (no result of z's)."""
    return pd.DataFrame(
        {
            "dataset": ["a"] * 6 + ["b"] * 3,
            "sequence": ["s1", "s1", "s1", "s2", "s2", "s2", "00", "00", "00"],
            "method": ["x", "y", "z"] * 3,
            "direction": "forward",
            "status": ["done", "done", "failed", "done", "done", "done", "done", "failed", "failed"],
            "failure": [None, None, "lost", None, None, None, None, "lost", "infra"],
            "eval_status": ["ok", "ok", None, "ok", "ok", "ok", "ok", None, None],
            "ate_rmse": [0.1, 0.2, np.nan, 0.3, 0.3, 0.1, 5.0, np.nan, np.nan],
        }
    )


def test_ranks_within_sequences_pool_and_a_failed_method_ranks_last(tmp_path):
    small_table().to_csv(tmp_path / "results.csv", index=False)
    out = stats_json(tmp_path / "results.csv")
    methods = out["pooled"]["methods"]
    # by hand: x 1, 2.5, 1; y 2, 2.5, 2 (lost: last); z 3 (lost: last), 1 and none in 00 (infra is no result)
    assert {m: methods[m]["mean_rank"] for m in "xyz"} == pytest.approx({"x": 1.5, "y": 6.5 / 3, "z": 2.0})
    assert {m: methods[m]["sequences_ranked"] for m in "xyz"} == {"x": 3, "y": 3, "z": 2}
    assert methods["y"]["success_pct"] == pytest.approx(200 / 3) and methods["z"]["infra"] == 1
    assert out["datasets"]["b"]["metrics"]["ate_rmse"]["medians"] == {"x": 5.0}  # KITTI's 00 read as text
    ate = np.array([0.1, 0.2, 0.3, 0.3, 0.1])  # dataset a's evaluated runs: one metric, z-scores squared
    assert out["datasets"]["a"]["mahalanobis"] == pytest.approx(((ate - ate.mean()) / ate.std(ddof=1)) ** 2)


def test_a_dataset_without_an_evaluated_run_gives_an_empty_block_not_an_error(tmp_path):
    df = small_table()
    df.loc[df.dataset == "b", ["status", "failure", "eval_status", "ate_rmse"]] = ["failed", "lost", None, np.nan]
    df.to_csv(tmp_path / "results.csv", index=False)
    p = slamrun("stats", tmp_path / "results.csv", "--json")
    assert p.returncode == 0, p.stderr
    block = strict_json(p.stdout)["datasets"]["b"]
    assert block == {
        "mahalanobis": [],
        "cutoff": None,
        "n_outliers": 0,
        "outlier_note": None,
        "counted": {},
        "counting_note": None,
        "coverage": {},
        "outlier_tests": [],
        "marks": {},
        "metrics": {},
    }
    assert "dataset b: 0 evaluated runs" in stats_out(tmp_path / "results.csv")
    p = slamrun("stats", tmp_path / "results.csv", "--metrics", "ate_rmse")
    assert (
        p.returncode == 1
        and p.stderr.startswith("slamrun: error: ")
        and "dataset 'b' has no value of ate_rmse" in p.stderr
    )


def test_serve_shows_every_datasets_report_figures_grouped_by_dataset(two_datasets, tmp_path):
    """A multi-dataset report writes report/datasets/NAME/figures/; `serve` looked in report/figures/ alone and said
    "no report yet" after the report was written. Each dataset's figures are listed under its name, and load."""
    import json

    from tests.test_report_page import chromium_page
    from tests.test_serve import get, serving

    folders = {p.parent.name: p for p in (two_datasets.results / "report" / "datasets").glob("*/figures")}
    assert set(folders) == {"euroc", "kitti"}
    with serving(two_datasets.results) as base:
        status, body, _ = get(base, "/c/results/api/state")
        assert status == 200
        figures = json.loads(body)["figures"]
        for name, folder in folders.items():
            listed = [f for f in figures if f["dataset"] == name]
            on_disk = {p.stem for p in folder.iterdir() if p.suffix == ".png"}
            assert on_disk and {f["name"] for f in listed} >= on_disk, (name, listed)
            for f in listed:
                assert f["path"].startswith(f"report/datasets/{name}/figures/")
                assert get(base, f"/c/results/files/{f['path']}")[0] == 200
        with chromium_page(f"{base}/c/results/", tmp_path / "profile") as page:  # a heading and grid per dataset
            heads = "[...document.querySelectorAll('#figures h3')].map(h => h.textContent).join(',')"
            assert page.until(heads, timeout_s=60) == "dataset euroc,dataset kitti"
            shown = "document.querySelectorAll('#figures .dataset-figures img').length"
            assert page.evaluate(shown) == sum(f["dataset"] is not None for f in figures)
