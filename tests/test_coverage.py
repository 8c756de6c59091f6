"""Coverage beside every figure: a method that writes a pose for every 5th frame (colmap's stride) beside one that
writes every frame, through a real campaign: results, statistics, tables, the live page's medians, and a dataset's
min_coverage that makes too sparse a run a tracking failure, said in the report."""

from __future__ import annotations

import json

import pandas as pd
import pytest

from slamrun.analysis.report import write_report
from slamrun.datasets.make_synthetic import generate
from slamrun.engine.campaign import run_campaign
from slamrun.engine.spec_file import load_spec
from tests.conftest import fake_method, write_spec


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    root = tmp_path_factory.mktemp("coverage")
    data = root / "data"
    for name, seed in (("seq_a", 1), ("seq_b", 2), ("seq_c", 3)):
        generate(data / name, frames=60, seed=seed, size=(160, 120), layout="euroc")
    methods = [
        fake_method(label="every", extra=["--noise", "0.01"]),
        fake_method(label="fifth", extra=["--noise", "0.01", "--every", "5"]),
    ]
    datasets = [
        {"name": "open", "path": str(data), "sequences": ["seq_a", "seq_b"], "layout": "euroc"},
        {"name": "strict", "path": str(data), "sequences": ["seq_c"], "layout": "euroc", "min_coverage": 0.5},
    ]
    spec = write_spec(root, data, methods, datasets=datasets, trials=2)
    res = run_campaign(load_spec(spec), log=lambda *a: None)
    return res, pd.read_csv(res.results_csv)


def test_coverage_and_like_for_like_rpe_in_results(campaign):
    _, df = campaign
    open_ = df[df.dataset == "open"].set_index("method")
    assert (open_.loc["every", "coverage"] == 1.0).all() and (open_.loc["fifth", "coverage"] == 0.2).all()
    assert (open_.status == "done").all() and (open_.rpe_interval == "1 s").all()
    # the same poses at the frames both have: RPE at one second agrees; the pairs are fewer, not longer
    every, fifth = (open_.loc[m].sort_values(["sequence", "direction"]) for m in ("every", "fifth"))
    assert fifth.rpe_t_rmse.to_numpy() == pytest.approx(every.rpe_t_rmse.to_numpy(), rel=0.25)
    assert (fifth.rpe_pairs.to_numpy() < every.rpe_pairs.to_numpy() / 4).all()


def test_min_coverage_makes_a_sparse_run_lost_and_the_report_says_so(campaign):
    res, df = campaign
    strict = df[df.dataset == "strict"]
    lost = strict[strict.method == "fifth"]
    assert (lost.status == "failed").all() and (lost.failure == "lost").all()
    assert lost.message.str.contains("poses for 20 % of its frames, under the dataset's min_coverage 0.5").all()
    assert (strict[strict.method == "every"].status == "done").all()
    html = write_report(res.results).read_text()
    assert "4 run(s) gave poses for fewer than min_coverage 0.5" in html
    assert "No coverage threshold (min_coverage) excluded a run" in html  # the open dataset's section


def test_statistics_and_tables_show_coverage(campaign):
    import subprocess
    import sys

    res, _ = campaign
    base = [sys.executable, "-m", "slamrun.cli", "stats", str(res.results), "--dataset", "open"]
    out = json.loads(subprocess.run([*base, "--json"], capture_output=True, text=True, check=True).stdout)
    assert out["datasets"]["open"]["coverage"] == {"every": 1.0, "fifth": 0.2}
    text = subprocess.run(base, capture_output=True, text=True, check=True).stdout
    said = "median coverage (share of the frames each method was given with a pose) of the runs tested: every 1, "
    said += "fifth 0.2"
    assert said in text
    write_report(res.results)
    table = pd.read_csv(res.results / "report" / "datasets" / "open" / "tables" / "trajectory_metrics.csv")
    assert table.set_index("method").loc["fifth", "coverage"] == pytest.approx(0.2)


def test_the_live_pages_medians_show_coverage(campaign):
    from slamrun.engine.ledger import Ledger
    from slamrun.serve.snapshot import medians

    res, _ = campaign
    ledger = Ledger(res.results / "ledger.sqlite", read_only=True)
    try:
        done = ledger.rows(status="done", columns=("method", "dataset", "coverage", "ate_rmse", "rpe_t_rmse"))
    finally:
        ledger.close()
    block = medians(done)["open"]
    assert block["metrics"][0] == "coverage"
    assert {m["method"]: m["coverage"] for m in block["methods"]} == {"every": 1.0, "fifth": 0.2}
