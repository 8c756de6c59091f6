"""Robustness campaigns end to end (issue 53): reference_vo and colmap on two synthetic rooms, forward and
backward, over two perturbations of two levels each; the ledger, results.csv, status and the report's Robustness
section carry them, and no perturbed run enters the study's tables. The tables' own logic on a hand-made table."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from slamrun.analysis.report import write_report
from slamrun.analysis.robustness import baseline, breakdown_table, level_statistics, success_rates
from slamrun.datasets.make_synthetic import generate
from slamrun.engine.campaign import run_campaign
from slamrun.engine.dryrun import dry_run
from slamrun.engine.session import read_figures
from slamrun.engine.spec_file import load_spec
from slamrun.results.vocabulary import level_text

AXIS = [{"kind": "gaussian_noise", "sigma": [4, 40]}, {"kind": "resolution", "scale": [0.5, 0.2]}]


@pytest.fixture(scope="module")
def campaign(tmp_path_factory) -> tuple[Path, Path]:
    """The campaign, run once: (its spec, its results folder)."""
    root = tmp_path_factory.mktemp("robust")
    for name, seed in (("room_a", 4), ("room_b", 6)):
        generate(root / "data" / name, frames=90, seed=seed, size=(320, 240))
    spec = {
        "name": "robust",
        "results": str(root / "results"),
        "cache": str(root / "cache"),
        "datasets": [{"name": "synth", "path": str(root / "data"), "sequences": ["room_a", "room_b"]}],
        "methods": [{"name": "reference_vo"}, {"name": "colmap", "params": {"max_features": 512}}],
        "perturbations": AXIS,
        "trials": 1,
        "lanes": 2,
        "timeout_s": 300,
        "report": False,
    }
    path = root / "spec.yaml"
    path.write_text(yaml.safe_dump(spec))
    before = dry_run(load_spec(path))
    assert before.total == 2 * 2 * 2 * 5 and before.perturbed_runs == 32
    assert before.perturbed_views == 16 and before.perturbed_bytes > 0  # 2 rooms x 2 directions x 4 levels
    result = run_campaign(load_spec(path), log=lambda *a: None)
    assert result.counts["pending"] == 0
    return path, root / "results"


def test_every_run_carries_its_perturbation_and_level(campaign):
    _, results = campaign
    df = pd.read_csv(results / "results.csv")
    assert len(df) == 40
    got = df.groupby(["perturbation", df.level.fillna(0)]).size().to_dict()
    assert got == {
        ("gaussian_noise", 4.0): 8,
        ("gaussian_noise", 40.0): 8,
        ("none", 0.0): 8,
        ("resolution", 0.2): 8,
        ("resolution", 0.5): 8,
    }
    perturbed = df[df.perturbation != "none"]
    for run_dir in perturbed.run_dir:
        record = json.loads((Path(run_dir) / "run.json").read_text())
        assert record["perturbation"] in ("gaussian_noise", "resolution") and record["level"] > 0
        view = json.loads((Path(record["view"]) / "view.json").read_text())
        assert view["perturbation"].startswith(record["perturbation"])  # it ran on its own view
        assert f"/{record['direction']}+{view['perturbation']}/" in run_dir
    vo = df[(df.perturbation == "none") & (df.method == "reference_vo")]
    assert (vo.status == "done").all(), "reference_vo tracks the rooms on the ordinary views"


def test_status_groups_by_how_the_sequence_was_played(campaign):
    _, results = campaign
    groups = {(g["method"], g["direction"]) for g in read_figures(results).per_group}
    assert ("reference_vo", "forward") in groups and ("colmap", "backward+resolution-0.2") in groups
    assert len(groups) == 2 * 2 * 5


def test_the_report_has_a_robustness_section_and_keeps_the_studys_tables_to_the_baseline(campaign):
    _, results = campaign
    index = write_report(results)
    html = index.read_text()
    assert "Robustness" in html and "Level at which the success rate falls under 50 %" in html
    assert "robustness_gaussian_noise.png" in html and "robustness_resolution.png" in html
    tables = index.parent / "tables"
    rates = pd.read_csv(tables / "robustness_success.csv")
    assert set(rates.level.astype(str)) == {"none", "4", "40", "0.5", "0.2"}
    assert set(rates.method) == {"reference_vo", "colmap"}
    breakdown = pd.read_csv(tables / "robustness_breakdown.csv", dtype=str)
    assert list(breakdown.columns) == ["method", "gaussian_noise (sigma)", "resolution (scale)"]
    df = pd.read_csv(results / "results.csv")
    failures = pd.read_csv(tables / "failures.csv")  # the study's runs table: the baseline's 8 runs alone
    assert failures.runs.sum() == len(baseline(df)) == 8
    for f in ("robustness_gaussian_noise.png", "robustness_resolution.png"):
        assert (index.parent / "figures" / f).stat().st_size > 10_000


def test_the_plan_states_what_the_axis_adds(campaign, capsys):
    from slamrun.cli import main

    spec, _ = campaign
    assert main(["plan", str(spec)]) == 0
    out = capsys.readouterr().out
    assert re.search(r"robustness: 32 of the 40 runs are on perturbed views", out)


# ------------------------------------------------------------------ the tables' logic on a hand-made table


def _runs(method: str, kind: str, level: float | None, done: int, failed: int, value: float) -> list[dict]:
    row = {"method": method, "perturbation": kind, "level": level, "sequence": "s", "direction": "forward"}
    rng = np.random.default_rng(abs(hash((method, kind, level))) % 2**32)
    out = []
    for i in range(done):
        out.append(
            row
            | {
                "trial": i,
                "status": "done",
                "failure": None,
                "eval_status": "ok",
                "ate_rmse": value * (1 + 0.1 * rng.random()),
            }
        )
    for i in range(failed):
        out.append(
            row | {"trial": done + i, "status": "failed", "failure": "lost", "eval_status": None, "ate_rmse": None}
        )
    out.append(row | {"trial": 99, "status": "failed", "failure": "infra", "eval_status": None, "ate_rmse": None})
    return out


def test_success_rates_breakdown_and_statistics_per_level():
    rows = []
    for m, base, fall in (("steady", 0.1, 10), ("fragile", 0.2, 1)):
        rows += _runs(m, "none", None, 10, 0, base)
        for sigma in (2.0, 10.0, 30.0):
            failed = min(10, int(sigma // fall)) if m == "fragile" else 0
            rows += _runs(m, "gaussian_noise", sigma, 10 - failed, failed, base * (1 + sigma / 10))
    df = pd.DataFrame(rows)
    rates = success_rates(df)
    fragile = rates[rates.method == "fragile"].set_index("level")["success %"].to_dict()
    assert fragile == {"none": 100.0, "2": 80.0, "10": 0.0, "30": 0.0}  # the infra run is no result
    br = breakdown_table(rates).set_index("method")["gaussian_noise (sigma)"].to_dict()
    assert br == {"fragile": "10", "steady": "never"}
    table, full = level_statistics(df, ["ate_rmse"])
    assert set(table.level) == {"2"}  # only level 2 has two methods with evaluated runs
    assert set(full) == {"gaussian_noise-2"}


def test_the_live_pages_medians_are_the_baselines_and_the_perturbed_runs_are_said_apart(campaign):
    """serve's page mixed the perturbed runs into the baseline's medians and box plot (issue 63): a method good on the
    baseline and lost on noisy views showed their median. Now its figures are the baseline's, as the report's and
    `stats`' are, and a line says how many runs on perturbed views the Robustness section has."""
    from slamrun.serve.snapshot import snapshot

    _, results = campaign
    df = pd.read_csv(results / "results.csv")
    base = baseline(df[df.status == "done"])
    live = snapshot(results, "robust")["medians"]["synth"]
    for row in live["methods"]:
        name = row["method"].split(" ")[0]
        mine = base[base.method == name]
        assert row["done"] == len(mine), name
        assert row["e_align"] == pytest.approx(mine.e_align.drop_duplicates().median()), name
        assert len(live["values"][name]) <= len(mine)
    perturbed = int((df.status == "done").sum() - len(base))
    assert any(f"{perturbed} done run(s) on perturbed views" in n for n in live["notes"]), live["notes"]


# ------------------------------------------------------------------ paired against each method's own baseline


def _room(method: str, sequence: str, kind: str, level: float | None, values: list[float | None]) -> list[dict]:
    """One run per trial: a value, or None for the method's failure (lost)."""
    row = {"method": method, "perturbation": kind, "level": level, "sequence": sequence, "direction": "forward"}
    out = []
    for trial, v in enumerate(values):
        done = v is not None
        out.append(
            row
            | {
                "trial": trial,
                "status": "done" if done else "failed",
                "failure": None if done else "lost",
                "eval_status": "ok" if done else None,
                "ate_rmse": v,
            }
        )
    return out


def _one_room_lost() -> pd.DataFrame:
    """`fragile` keeps its accuracy on room_a under noise and is lost on room_b; `steady` gets twice as bad on both."""
    rows = []
    for m in ("fragile", "steady"):
        for seq in ("room_a", "room_b"):
            rows += _room(m, seq, "none", None, [0.10, 0.12])
    rows += _room("fragile", "room_a", "gaussian_noise", 10.0, [0.11, 0.12])
    rows += _room("fragile", "room_b", "gaussian_noise", 10.0, [None, None])
    for seq in ("room_a", "room_b"):
        rows += _room("steady", seq, "gaussian_noise", 10.0, [0.20, 0.24])
    # an infrastructure failure is no result: left out of the pairs, as of the success rate
    rows.append(rows[-1] | {"trial": 2, "status": "failed", "failure": "infra", "eval_status": None, "ate_rmse": None})
    return pd.DataFrame(rows)


def test_a_method_lost_on_one_room_is_counted_in_its_paired_figures_not_hidden_by_its_survivors():
    """The survivors' median made `fragile` look unharmed (0.115 against its baseline's 0.11) where it was lost on
    half its runs; paired with its own baseline, run by run, its failures count at infinity."""
    from slamrun.analysis.robustness import AREA_BOUND, area, paired_table, pairs, spread

    df = _one_room_lost()
    survivors = spread(df, "gaussian_noise", "ate_rmse").set_index(["method", "level"])["median"]
    assert survivors["fragile", "10"] == pytest.approx(0.115)  # what the absolute figure shows

    p = pairs(df, "gaussian_noise", "ate_rmse")
    fragile = p[p.method == "fragile"].sort_values(["sequence", "trial"])
    assert list(fragile.ratio) == pytest.approx([1.1, 1.0, np.inf, np.inf])
    assert len(p[p.method == "steady"]) == 4  # the infra run made no pair

    table = paired_table(df, "ate_rmse").set_index(["perturbation", "level", "method"])
    f, s = table.loc["gaussian_noise", "10", "fragile"], table.loc["gaussian_noise", "10", "steady"]
    assert (f.pairs, f.failed, s.pairs, s.failed) == (4, 2, 4, 0)
    assert f["median ratio"] == np.inf  # half its pairs failed: its median is a failure
    assert s["median ratio"] == pytest.approx(2.0)
    # the area under the cumulative curve of ratios 1..AREA_BOUND (log), failures never reached, over all pairs
    one_point_one = 1 - np.log(1.1) / np.log(AREA_BOUND)
    assert f.area == pytest.approx((one_point_one + 1.0 + 0 + 0) / 4)
    assert s.area == pytest.approx(1 - np.log(2.0) / np.log(AREA_BOUND))
    assert area(np.array([0.5, 1.0, AREA_BOUND, 20.0, np.inf])) == pytest.approx(2 / 5)


def test_a_pair_needs_its_baseline_and_says_so():
    """A perturbed run whose baseline run failed has nothing to be compared with: no pair, counted apart."""
    from slamrun.analysis.robustness import paired_table, pairs

    rows = _room("m", "room_a", "none", None, [None, 0.1]) + _room("m", "room_a", "gaussian_noise", 4.0, [0.1, 0.3])
    df = pd.DataFrame(rows)
    p = pairs(df, "gaussian_noise", "ate_rmse")
    assert np.isnan(p.ratio.iloc[0]) and p.ratio.iloc[1] == pytest.approx(3.0)
    row = paired_table(df, "ate_rmse").iloc[0]
    assert (row.pairs, row["without baseline"]) == (1, 1)


def test_the_summary_gives_each_kinds_area_and_breakdown_per_method():
    from slamrun.analysis.robustness import summary_table

    df = _one_room_lost()
    summary = summary_table(df, "ate_rmse").set_index("method")
    assert list(summary.columns) == ["gaussian_noise area", "gaussian_noise breakdown"]
    assert summary.loc["fragile", "gaussian_noise breakdown"] == "never"  # 50 % success is not under 50 %
    assert summary.loc["steady", "gaussian_noise area"] > summary.loc["fragile", "gaussian_noise area"]


def _without_baseline_failed(df: pd.DataFrame, runs: pd.DataFrame) -> int:
    """Of `runs`, the method's failures whose baseline run has no figure (no pair: not among the pairs' failures)."""
    base = df[(df.perturbation == "none") & (df.status == "done") & df.e_align.notna()]
    keys = set(zip(base.method, base.sequence, base.direction, base.trial, strict=True))
    failed = runs[(runs.status == "failed") & ~runs.failure.isin(["infra", "contended"])]
    return sum(k not in keys for k in zip(failed.method, failed.sequence, failed.direction, failed.trial, strict=True))


def test_the_report_pairs_each_run_with_its_baseline_and_writes_robustness_csv(campaign):
    """The real campaign: every perturbed run with a result is in its level's pairs or counted without a baseline,
    results/robustness.csv holds each dataset's levels, and the curves figure is drawn per kind."""
    _, results = campaign
    index = write_report(results)
    df = pd.read_csv(results / "results.csv")
    robust = pd.read_csv(results / "robustness.csv", keep_default_na=False, na_values=[""])
    perturbed = robust[robust.level != "none"]
    assert set(perturbed.perturbation) == {"gaussian_noise", "resolution"}
    assert set(robust.metric) == {"e_align"} and set(robust.dataset) == {"synth"}
    summary_at = robust.drop_duplicates(["perturbation", "method"]).set_index(["method", "perturbation"])["breakdown"]
    breakdown = pd.read_csv(index.parent / "tables" / "robustness_breakdown.csv", dtype=str).set_index("method")
    for (method, kind), level in summary_at.items():
        assert str(level) == breakdown.at[method, f"{kind} ({'sigma' if kind == 'gaussian_noise' else 'scale'})"]
    for _, row in perturbed.iterrows():
        runs = df[(df.perturbation == row.perturbation) & (df.method == row.method)]
        runs = runs[runs.level.map(level_text) == row.level]
        figure = (runs.status == "done") & runs.e_align.notna()
        own_failure = (runs.status == "failed") & ~runs.failure.isin(["infra", "contended"])
        assert row["pairs"] + row["without baseline"] == (figure | own_failure).sum()
        assert row["failed"] == own_failure.sum() - _without_baseline_failed(df, runs)
    tables = index.parent / "tables"
    summary = pd.read_csv(tables / "robustness_summary.csv")
    assert list(summary.columns) == [
        "method",
        "gaussian_noise area",
        "gaussian_noise breakdown",
        "resolution area",
        "resolution breakdown",
    ]
    assert summary[["gaussian_noise area", "resolution area"]].stack().between(0, 1).all()
    for kind in ("gaussian_noise", "resolution"):
        assert (index.parent / "figures" / f"robustness_curves_{kind}.png").stat().st_size > 10_000


def test_a_scheduled_perturbation_is_a_condition_of_its_own_in_the_section(tmp_path):
    """Static noise and the same noise in bursts, side by side: two conditions, each with its tables and figures
    (file names without the schedule's ':' and '/')."""
    from slamrun.analysis.report import robustness_report
    from slamrun.analysis.robustness import kinds, summary_table

    static = _one_room_lost()
    burst = static[static.perturbation != "none"].assign(perturbation="gaussian_noise@burst:3/10")
    df = pd.concat([static, burst], ignore_index=True)
    assert kinds(df) == ["gaussian_noise", "gaussian_noise@burst:3/10"]
    summary = summary_table(df, "ate_rmse")
    assert "gaussian_noise@burst:3/10 area" in summary.columns
    sections = robustness_report(df, tmp_path, tmp_path, "synth")
    assert sections and (tmp_path / "figures" / "robustness_gaussian_noise-burst3of10.png").is_file()
    assert (tmp_path / "figures" / "robustness_curves_gaussian_noise-burst3of10.png").is_file()
