"""Every view tells the same story (issue 62): each metric's statistics, tables and figures take every run with a
figure of that metric (a run without KITTI's segment figure stays in ATE's), every view of a dataset section shows
its methods or says in one line who it leaves out and why, and copies of a run count once everywhere (motion bias,
cumulative plots, medians).

A real campaign: a synthetic KITTI drive (two laps, about 130 m), three methods (real processes writing real
trajectories): `full` tracks the whole drive, `short` the first fifth of it (about 26 m: ATE and RPE, no segment of
KITTI's 100 m), `copies` is deterministic (its two trials are one run); forward and backward, two trials."""

from __future__ import annotations

import contextlib
import io
import json
import re

import numpy as np
import pandas as pd
import pytest

from slamrun.analysis.stats import study_statistics, wilcoxon_rank_sum_p
from slamrun.analysis.tables import motion_bias_table
from slamrun.cli import main
from slamrun.datasets.make_synthetic import generate
from tests.conftest import fake_method, write_spec


@pytest.fixture(scope="module")
def kitti(tmp_path_factory):
    root = tmp_path_factory.mktemp("every_view")
    generate(
        root / "kitti" / "sequences" / "00", frames=200, seed=2, size=(160, 120), layout="kitti", scene_kind="outdoor"
    )
    datasets = [{"name": "kitti", "path": str(root / "kitti" / "sequences"), "sequences": ["00"], "layout": "kitti"}]
    methods = [
        fake_method(label="full", extra=["--noise", "0.05", "--vary"]),
        fake_method(label="short", extra=["--noise", "0.01", "--vary", "--part", "0.2"]),
        fake_method(label="copies", extra=["--noise", "0.08"]),
    ]
    spec = write_spec(root, root, methods, datasets=datasets, trials=2, report=True)
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(["campaign", str(spec)]) == 0
    results = root / "results"
    df = pd.read_csv(results / "results.csv", dtype={"sequence": str})
    (results / "campaign-output.txt").write_text(buf.getvalue())
    return results, df


def cli(*args) -> str:
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main([*map(str, args)]) == 0
    return buf.getvalue()


def test_the_campaign_is_what_the_views_are_tested_on(kitti):
    _, df = kitti
    assert df.status.eq("done").all() and len(df) == 12
    short = df[df.method == "short"]
    assert short.ate_rmse.notna().all() and short.kitti_t_pct.isna().all()
    assert df[df.method != "short"].kitti_t_pct.notna().all()


def test_a_run_without_one_metric_stays_in_the_others_tests(kitti):
    """The issue's reproduction: `stats --metrics ate_rmse kitti_t_pct` left `short` out of ATE's medians."""
    results, _ = kitti
    for args in ((), ("--metrics", "ate_rmse", "kitti_t_pct")):
        st = json.loads(cli("stats", results, "--json", *args))["datasets"]["kitti"]["metrics"]
        assert set(st["ate_rmse"]["medians"]) == {"full", "short", "copies"}, args
        assert st["ate_rmse"]["runs"] == {"copies": 2, "full": 4, "short": 4}
        assert set(st["kitti_t_pct"]["medians"]) == {"full", "copies"}
        assert "100 m" in st["kitti_t_pct"]["left_out"]["short"]
    text = cli("stats", results, "--metrics", "ate_rmse", "kitti_t_pct")
    assert re.search(r"not in this metric's tests: short \(no figure in its 4 done run\(s\): .*100 m", text), text


def test_every_view_of_the_section_shows_the_method_or_says_why_not(kitti):
    results, _ = kitti
    tables = results / "report" / "tables"
    traj = pd.read_csv(tables / "trajectory_metrics.csv")
    row = traj.set_index("method").loc["short"]
    assert np.isfinite(row.ate_rmse) and np.isnan(row.kitti_t_pct) and row["runs"] == 4
    html = (results / "report" / "index.html").read_text()
    said = re.findall(r'<p class="note">Not shown: short \(([^<]*)\)', html)
    assert said and all("100 m" in s for s in said), said  # the KITTI columns, tests, box plots of KITTI's errors
    # ATE's figures and tables name it, KITTI's say why it is absent
    for name in ("box_ate_rmse", "cumulative_ate_rmse", "box_rpe_t_rmse"):
        assert "short" in (results / "report" / "figures" / f"{name}.svg").read_text(), name
    assert "short" not in (results / "report" / "figures" / "box_kitti_t_pct.svg").read_text()
    box = html.index("box_kitti_t_pct.png")
    assert "Not shown: short" in html[box : html.index("</figure>", box)]


def test_copies_count_once_in_motion_bias_cumulative_plots_and_medians(kitti):
    results, df = kitti
    copies = df[df.method == "copies"]
    assert copies.groupby("direction").ate_rmse.nunique().eq(1).all()  # the method is deterministic
    mb = pd.read_csv(results / "report" / "tables" / "motion_bias.csv").set_index("method")
    assert mb.loc["copies", "n forward"] == 1 and mb.loc["copies", "n backward"] == 1
    one_trial = motion_bias_table(df[df.trial == 0], "ate_rmse").set_index("method")
    pd.testing.assert_series_equal(
        mb.loc["copies"].drop("marks").astype(float), one_trial.loc["copies"], check_names=False
    )  # one trial's
    full = df[df.method == "full"]
    fw, bw = (full.loc[full.direction == d, "ate_rmse"].to_numpy() for d in ("forward", "backward"))
    assert mb.loc["full", "p (rank-sum)"] == pytest.approx(wilcoxon_rank_sum_p(fw, bw))  # R's rank-sum test
    svg = (results / "report" / "figures" / "cumulative_ate_rmse.svg").read_text()
    assert "copies (n=2)" in svg and "full (n=4)" in svg


def test_a_table_of_runs_with_a_metric_missing_keeps_them_in_the_other_metrics():
    """The rule on a plain table: ATE's tests take the run without KITTI's figure; the outlier test takes each run
    on the metrics it has."""
    rng = np.random.default_rng(1)
    rows = []
    for method, centre, kitti in (("a", 0.1, True), ("b", 0.3, True), ("c", 0.02, False)):
        for k in range(6):
            rows.append(
                {
                    "method": method,
                    "sequence": f"s{k % 3}",
                    "direction": "forward" if k < 3 else "backward",
                    "ate_rmse": centre * (1 + 0.1 * rng.random()),
                    "kitti_t_pct": (2 + rng.random()) if kitti else np.nan,
                }
            )
    st = study_statistics(pd.DataFrame(rows), ["ate_rmse", "kitti_t_pct"])
    assert set(st.metrics["ate_rmse"].medians) == {"a", "b", "c"}
    assert set(st.metrics["kitti_t_pct"].medians) == {"a", "b"}
    assert [t["metrics"] for t in st.outlier_tests] == [["ate_rmse", "kitti_t_pct"], ["ate_rmse"]]
    assert st.outlier_tests[1]["population"] == 18 and st.outlier_tests[1]["runs"] == 6


def test_a_diverged_run_is_flagged_everywhere_and_a_failure_where_the_dataset_says_so(tmp_path):
    """glomap's spiral on a 129 m drive was `done`, 100 % success (issue 62). `ate_rel` (ATE over the ground truth's
    spread) flags a run over 0.5 in results.csv even where the dataset sets no threshold; with `max_ate_rel` such a
    run is a tracking failure, `diverged`, charged to the method."""
    data = tmp_path / "data"
    for name, seed in (("seq_a", 1), ("seq_b", 2)):
        generate(data / name, frames=60, seed=seed, size=(160, 120), layout="euroc")
    methods = [
        fake_method(label="steady", extra=["--noise", "0.01", "--vary"]),
        fake_method(label="spiral", extra=["--noise", "0.01", "--diverge", "0.05"]),
    ]
    datasets = [
        {"name": "open", "path": str(data), "sequences": ["seq_a"], "layout": "euroc"},
        {"name": "strict", "path": str(data), "sequences": ["seq_b"], "layout": "euroc", "max_ate_rel": 0.5},
    ]
    spec = write_spec(tmp_path, data, methods, datasets=datasets, trials=1, report=True)
    assert main(["campaign", str(spec)]) == 0
    df = pd.read_csv(tmp_path / "results" / "results.csv")
    steady, spiral = df[df.method == "steady"], df[df.method == "spiral"]
    assert (steady.ate_rel < 0.1).all() and (steady.diverged == 0).all() and (steady.status == "done").all()
    assert (spiral.ate_rel > 0.5).all() and (spiral.diverged == 1).all()
    open_, strict = spiral[spiral.dataset == "open"], spiral[spiral.dataset == "strict"]
    assert (open_.status == "done").all()  # flagged, not failed: the dataset sets no threshold
    assert (strict.status == "failed").all() and (strict.failure == "diverged").all()
    assert strict.message.str.contains("over the dataset's max_ate_rel 0.5").all()


def test_ate_rel_is_near_one_for_an_estimate_without_likeness_and_zero_for_a_similar_one():
    from slamrun.core.metrics import ate
    from slamrun.core.trajectory import Trajectory

    t = np.arange(50) * 0.1
    path = np.column_stack([np.cos(t), np.sin(t), 0.1 * t])
    quats = np.tile([0.0, 0.0, 0.0, 1.0], (50, 1))
    gt = Trajectory(t, path, quats)
    noise = Trajectory(t, np.random.default_rng(0).normal(size=(50, 3)), quats)  # no likeness to the path
    rel = ate(gt, noise).relative
    assert 0.8 < rel <= 1.0  # under Sim(3) the alignment can always shrink it to a point: at most 1
    assert ate(gt, Trajectory(t, 2 * path + 1, quats)).relative == pytest.approx(0.0, abs=1e-9)


def test_a_method_tracking_under_the_coverage_mark_is_marked_in_every_view(kitti):
    """`short` posed a fifth of the frames it was given (under coverage_mark 0.5): no view shows it as best, bold or
    ranked first without its mark, and the mark is said under each view."""
    from slamrun.engine.ledger import Ledger
    from slamrun.serve.snapshot import MEDIAN_COLUMNS, medians

    results, df = kitti
    short = df[df.method == "short"]
    assert short.coverage.between(0.19, 0.21).all() and short.low_coverage.eq(1).all()
    assert df[df.method != "short"].low_coverage.eq(0).all()
    said = "† low coverage: done runs with poses for fewer than 0.5 of the frames their method was given (short 4 of 4)"
    terminal = (results / "campaign-output.txt").read_text()
    assert "short †" in terminal and said in " ".join(terminal.split())
    assert "short †" in cli("stats", results) and said in cli("stats", results)
    assert json.loads(cli("stats", results, "--json"))["datasets"]["kitti"]["marks"]["short"]["mark"] == "†"
    html = (results / "report" / "index.html").read_text()
    assert html.count(said) >= 6  # under the runs table, the medians tables, motion bias, the figures ...
    tables = results / "report" / "tables"
    traj = pd.read_csv(tables / "trajectory_metrics.csv").set_index("method")
    assert traj.loc["short", "marks"] == "†" and traj.loc["full", "marks"] != "†"
    assert "short †" in (tables / "trajectory_metrics.tex").read_text()
    assert "short †" in (tables / "trajectory_metrics.md").read_text()
    for name in ("box_ate_rmse", "cumulative_ate_rmse", "heatmap_ate_rmse"):
        assert "short †" in (results / "report" / "figures" / f"{name}.svg").read_text(), name
    ledger = Ledger(results / "ledger.sqlite", read_only=True)
    try:
        live = medians(ledger.rows(status="done", columns=MEDIAN_COLUMNS))["kitti"]
    finally:
        ledger.close()
    assert "short †" in {m["method"] for m in live["methods"]} and said in live["notes"][0]
    copies = next(m for m in live["methods"] if m["method"] == "copies")
    assert len(live["values"]["copies"]) == 2  # its 4 runs are 2 distinct ones
    assert copies["ate_rmse"] == pytest.approx(df[df.method == "copies"].ate_rmse.median())


@pytest.mark.parametrize("power", [155, 80])
def test_poses_that_explode_are_a_tracking_failure_never_a_success(tmp_path, power):
    """Poses good for the first half, then growing to 1e155 were `done` without a figure ('degenerate alignment'),
    100 % success; to 1e80 they were evaluated, e_align 2.5e80 (issue 63). Output no metric can use is the method's
    failure, `diverged`, with a message saying so; no run without figures counts as a success."""
    data = tmp_path / "data"
    generate(data / "seq_a", frames=60, seed=1, size=(160, 120))
    methods = [fake_method(label="exploding", extra=["--blow-up", str(power)]), fake_method(label="steady")]
    spec = write_spec(tmp_path, data, methods, datasets=[{"name": "s", "path": str(data), "sequences": ["seq_a"]}])
    assert main(["campaign", str(spec)]) == 0
    df = pd.read_csv(tmp_path / "results" / "results.csv")
    bad = df[df.method == "exploding"]
    assert (bad.status == "failed").all() and (bad.failure == "diverged").all(), bad[["status", "failure", "message"]]
    assert bad.message.str.contains("poses explode").all(), bad.message.tolist()
    assert bad.e_align.isna().all()
    st = json.loads(cli("stats", tmp_path / "results", "--json"))["pooled"]["methods"]
    assert st["exploding"]["success_pct"] == 0 and st["steady"]["success_pct"] == 100
