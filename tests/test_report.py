"""The report: tables and figures from a results table, and index.html rendered in headless Chromium."""

from __future__ import annotations

import json
import os
import shutil
import subprocess

import numpy as np
import pandas as pd
import pytest

from runner.analysis.report import write_report
from runner.cli import main


def fake_results(tmp_path, n_methods=3, n_seq=4, trials=5) -> pd.DataFrame:
    """A results table shaped like a campaign's (values drawn at random: the report's inputs, not its goldens)."""
    rng = np.random.default_rng(1)
    rows = []
    for mi in range(n_methods):
        for s in range(n_seq):
            for d in ("forward", "backward"):
                for t in range(trials):
                    failed = rng.random() < 0.1
                    scale = 1 + mi
                    row = {
                        "method": f"m{mi}",
                        "sequence": f"sequence_{s:02d}",
                        "direction": d,
                        "trial": t,
                        "status": "failed" if failed else "done",
                        "failure": "lost" if failed else None,
                        "eval_status": None if failed else "ok",
                        "wall_s": rng.uniform(10, 20),
                        "fps": rng.uniform(20, 40),
                        "cpu_mean_pct": rng.uniform(50, 100),
                        "cpu_peak_pct": rng.uniform(100, 150),
                        "ram_peak_mb": rng.uniform(100, 300),
                        "gpu_mem_peak_mb": np.nan,
                        "run_dir": str(tmp_path / "nowhere"),
                    }
                    for m in ("e_t", "e_r", "e_start", "e_end", "e_rmse", "e_align"):
                        row[m] = np.nan if failed else rng.lognormal(np.log(0.1 * scale), 0.5)
                    row["e_s"] = np.nan if failed else rng.lognormal(0, 0.05 * scale)
                    row["e_s_sym"] = np.nan if failed else max(row["e_s"], 1 / row["e_s"])
                    rows.append(row)
    return pd.DataFrame(rows)


def test_report_files(tmp_path):
    fake_results(tmp_path).to_csv(tmp_path / "results.csv", index=False)
    index = write_report(tmp_path)
    tables = {p.name for p in (tmp_path / "report" / "tables").iterdir()}
    for name in (
        "table3_drift",
        "table4_segments",
        "table2_resources",
        "failures",
        "motion_bias",
        "table3_drift_forward",
        "table3_drift_backward",
        "e_align_per_sequence",
    ):
        assert {f"{name}.csv", f"{name}.md", f"{name}.tex"} <= tables
    figs = {p.name for p in (tmp_path / "report" / "figures").iterdir()}
    for name in (
        "cumulative_e_t",
        "cumulative_e_r",
        "cumulative_e_s_sym",
        "cumulative_e_start",
        "cumulative_e_end",
        "cumulative_e_align_motion_bias",
        "heatmap_e_align",
        "box_e_t",
    ):
        assert {f"{name}.png", f"{name}.svg"} <= figs
    assert (tmp_path / "report" / "statistics_forward.json").exists()
    html = index.read_text()
    assert html.count("<img") >= 13 and "Kruskal-Wallis" in html
    t3 = pd.read_csv(tmp_path / "report" / "tables" / "table3_drift.csv")
    assert t3.method.iloc[-1] == "Kruskal-Wallis chi2" and t3.method.iloc[0] == "m0"  # best first
    failures = pd.read_csv(tmp_path / "report" / "tables" / "failures.csv")
    assert failures.lost.sum() == fake_results(tmp_path).failure.eq("lost").sum()  # counted, not dropped


def test_stats_cli_json(tmp_path, shared_data, capsys):
    assert main(["stats", str(shared_data / "stats_golden" / "observations.csv"), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert list(out["datasets"]) == ["all"]  # a table without a dataset column: one block
    out = out["datasets"]["all"]
    ref = json.loads((shared_data / "stats_golden" / "r_reference.json").read_text())
    assert set(out) == set(ref) and set(out["metrics"]) == set(ref["metrics"])
    assert out["n_outliers"] == ref["n_outliers"]
    assert set(out["metrics"]["e_t"]) >= set(ref["metrics"]["e_t"])


def render_in_chromium(index, tmp_path):
    """Open the report in headless Chromium: every figure must decode and lay out; returns a screenshot."""
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        pytest.skip(reason="Chromium not installed (apt-get install chromium); .ci/run installs it")
    flags = [
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-quic",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        f"--user-data-dir={tmp_path / 'profile'}",
    ]
    dom = subprocess.run(
        [chromium, *flags, "--virtual-time-budget=5000", "--dump-dom", index.as_uri()],
        capture_output=True,
        text=True,
        timeout=120,
    ).stdout
    n_img = index.read_text().count("<img")
    assert f'data-images-loaded="{n_img}/{n_img}"' in dom  # every figure decoded and laid out
    shot = index.parent / "screenshot.png"
    subprocess.run(
        [chromium, *flags, "--window-size=1200,3000", f"--screenshot={shot}", index.as_uri()],
        capture_output=True,
        timeout=120,
    )
    assert shot.exists() and shot.stat().st_size > 10_000
    if os.environ.get("SLAMRUN_KEEP_SHOT"):  # to look at the rendered report yourself
        shutil.copy(shot, os.environ["SLAMRUN_KEEP_SHOT"])
    return shot


def test_report_renders_in_chromium(tmp_path):
    fake_results(tmp_path).to_csv(tmp_path / "results.csv", index=False)
    render_in_chromium(write_report(tmp_path), tmp_path)


def test_a_campaign_with_ate_and_rpe_has_their_table_and_the_paths(tmp_path, tiny_dataset):
    """A campaign whose dataset asks for ATE and RPE beside TUM-Mono's metrics: the results carry them, the
    report has their table with letters and, per sequence, each method's best, median and worst path over the
    ground truth, rendered in a real browser."""
    from runner.engine.campaign import run_campaign
    from runner.engine.spec import load_spec
    from tests.conftest import fake_method, write_spec

    datasets = [
        {"name": "s", "path": str(tiny_dataset), "sequences": ["seq_a", "seq_b"], "metrics": ["tum-mono", "ate", "rpe"]}
    ]
    spec = write_spec(
        tmp_path,
        tiny_dataset,
        [
            fake_method(label="steady", extra=["--noise", "0.002"]),
            fake_method(label="shaky", extra=["--noise", "0.02"]),
        ],
        datasets=datasets,
        trials=3,
        report=True,
    )
    res = run_campaign(load_spec(spec), on_event=None)
    df = pd.read_csv(res.results_csv)
    assert df.status.eq("done").all() and df.ate_rmse.notna().all() and df.rpe_t_rmse.notna().all()
    assert df.coverage.eq(1.0).all()  # the fake method gives every frame a pose
    medians = df.groupby("method").ate_rmse.median()
    assert medians["steady"] < medians["shaky"]
    index = write_report(res.results)
    table = pd.read_csv(res.results / "report" / "tables" / "trajectory_metrics.csv")
    assert {"ate_rmse", "rpe_t_rmse", "rpe_r_rmse"} <= set(table.columns)
    assert (res.results / "report" / "figures" / "trajectories_seq_a.png").exists()
    render_in_chromium(index, tmp_path)


def test_a_campaign_without_tum_mono_metrics_reports_its_own(tmp_path):
    """EuRoC, KITTI, TUM RGB-D campaigns have ATE and RPE only: the motion-bias and per-sequence tables and the
    figures use ATE, and no empty TUM-Mono figure is drawn."""
    df = fake_results(tmp_path)
    rng = np.random.default_rng(2)
    done = df.status == "done"
    df = df.drop(columns=[c for c in df.columns if c.startswith("e_")])
    df.loc[done, "ate_rmse"] = rng.uniform(0.01, 0.1, int(done.sum()))
    df.loc[done, "rpe_t_rmse"] = rng.uniform(0.001, 0.01, int(done.sum()))
    df.to_csv(tmp_path / "results.csv", index=False)
    write_report(tmp_path)
    tables, figs = tmp_path / "report" / "tables", tmp_path / "report" / "figures"
    bias = pd.read_csv(tables / "motion_bias.csv")
    assert {"median ate_rmse forward", "median ate_rmse backward"} <= set(bias.columns)
    assert (tables / "ate_rmse_per_sequence.csv").exists()
    assert (figs / "cumulative_ate_rmse.png").exists() and (figs / "heatmap_ate_rmse.png").exists()
    assert not list(figs.glob("cumulative_e_*.png"))
