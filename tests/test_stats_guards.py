"""No test says more than its data can: copies of a run count once, and a test whose input cannot support it
(no spread to rounding, all values tied, fewer runs than metrics) gives no figure but its reason."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest
from scipy import stats as scipy_stats

from slamrun.analysis.stats import distinct_runs, levene, study_statistics, wilcoxon_rank_sum_p


def runs(method: str, values: dict[tuple[str, str], list[float]]) -> list[dict]:
    return [
        {"method": method, "sequence": s, "direction": d, "trial": k, "ate_rmse": v}
        for (s, d), vs in values.items()
        for k, v in enumerate(vs)
    ]


def deterministic_and_random() -> pd.DataFrame:
    """The issue's case: one method's three trials per sequence and direction are copies (4 distinct values, 12
    rows); the other's trials differ."""
    cells = [("s1", "forward"), ("s1", "backward"), ("s2", "forward"), ("s2", "backward")]
    same = {c: [0.1 + 0.01 * i] * 3 for i, c in enumerate(cells)}
    rng = np.random.default_rng(3)
    varied = {c: list(0.2 + 0.05 * rng.random(3)) for c in cells}
    return pd.DataFrame(runs("copies", same) + runs("varied", varied))


def test_copies_count_once_and_the_p_value_is_that_of_the_distinct_runs():
    df = deterministic_and_random()
    st = study_statistics(df, ["ate_rmse"])
    assert st.counted["copies"] == {"runs": 12, "distinct": 4, "deterministic": True}
    assert st.counted["varied"] == {"runs": 12, "distinct": 12, "deterministic": False}
    assert st.deterministic == ["copies"]
    assert "copies 4 of 12 (deterministic: identical trials)" in st.counting_note()
    distinct = df.drop_duplicates(["method", "sequence", "direction", "ate_rmse"])
    a, b = (distinct.loc[distinct.method == m, "ate_rmse"].to_numpy() for m in ("copies", "varied"))
    (pair,) = st.metrics["ate_rmse"].pairwise_none
    assert pair["p"] == pytest.approx(wilcoxon_rank_sum_p(a, b), rel=1e-12)
    inflated = wilcoxon_rank_sum_p(*(df.loc[df.method == m, "ate_rmse"].to_numpy() for m in ("copies", "varied")))
    assert inflated < pair["p"] / 5  # what counting the copies would have claimed


def test_a_plain_table_of_observations_is_not_deduplicated():
    """Without sequence and direction columns (R's reference observations) every row is a sample."""
    df = pd.DataFrame({"method": ["a"] * 3 + ["b"] * 3, "x": [1.0, 1.0, 2.0, 3.0, 3.0, 4.0]})
    out, counted = distinct_runs(df, ["x"])
    assert len(out) == 6 and counted == {}


def test_levene_on_groups_without_spread_to_rounding_is_null_with_its_reason():
    """scipy (and R's car) give an F from groups whose spread is one unit in the last place (4.5e34 in the issue's
    campaign, 0.71 here): a number that means nothing, once printed as a result."""
    groups = [np.array([0.3, 0.3, 0.3]), np.array([0.1 + 0.2, 0.3, 0.3, 0.3])]
    with np.errstate(all="ignore"):
        raw = scipy_stats.levene(*groups, center="median").statistic
    assert np.isfinite(raw)  # what was printed before
    f, p = levene(groups)
    assert np.isnan(f) and np.isnan(p)
    df = pd.DataFrame(
        {
            "method": ["a"] * 3 + ["b"] * 4,
            "sequence": ["s1", "s2", "s3", "s1", "s2", "s3", "s4"],
            "direction": "forward",
            "ate_rmse": np.concatenate(groups),
        }
    )
    m = study_statistics(df, ["ate_rmse"]).metrics["ate_rmse"]
    assert np.isnan(m.levene_F) and "no spread within any method's runs" in m.notes["levene"]
    assert "kruskal" in m.notes  # 0.3 and 0.30000000000000004 are one value


def test_levene_on_groups_of_two_distinct_values_is_null_with_its_reason():
    """Two values per group: each lies as far from the group's median as the other, so the absolute deviations that
    Levene's test compares have no spread within any group and its F divides by zero (the issue: F 1.27e+30, p
    1.3e-45; F inf, p 0.0). The test's own input has no spread: no figure, the reason said."""
    groups = [np.array([0.1, 0.3]), np.array([0.2, 0.7]), np.array([0.15, 0.16])]
    with np.errstate(all="ignore"):
        raw = scipy_stats.levene(*groups, center="median")
    assert not np.isfinite(raw.statistic) or raw.statistic > 1e10  # what was printed before
    f, p = levene(groups)
    assert np.isnan(f) and np.isnan(p)
    df = pd.DataFrame(
        {
            "method": ["a", "a", "b", "b", "c", "c"],
            "sequence": ["s1", "s2"] * 3,
            "direction": "forward",
            "ate_rmse": np.concatenate(groups),
        }
    )
    m = study_statistics(df, ["ate_rmse"]).metrics["ate_rmse"]
    assert np.isnan(m.levene_F) and "absolute deviations" in m.notes["levene"]
    assert np.isfinite(m.kruskal_p)  # the values themselves spread: the rank test stands
    # one group whose deviations do spread: the test has within-group variance and gives its figure
    f, p = levene([*groups, np.array([0.1, 0.2, 0.9])])
    assert np.isfinite(f) and 0 <= p <= 1


def test_all_values_tied_gives_no_rank_test_and_no_letters_apart():
    df = pd.DataFrame({"method": ["a", "a", "b", "b"], "ate_rmse": [0.5] * 4})
    m = study_statistics(df, ["ate_rmse"]).metrics["ate_rmse"]
    assert np.isnan(m.kruskal_p) and "nothing to rank" in m.notes["kruskal"]
    assert np.isnan(m.pairwise_none[0]["p"]) and m.letters == {"a": "a", "b": "a"}


def test_mahalanobis_needs_more_runs_than_metrics():
    df = pd.DataFrame({"method": ["a", "b"], "e_t": [1.0, 2.0], "e_r": [1.0, 3.0], "e_s": [1.0, 1.1]})
    st = study_statistics(df, ["e_t", "e_r", "e_s"])
    assert st.mahalanobis == [] and st.n_outliers == 0 and len(st.kept) == 2
    assert "2 run(s) for 3 metric(s)" in st.outlier_note
    assert st.to_json()["outlier_note"] == st.outlier_note


def test_a_campaign_with_a_deterministic_method_says_so(tmp_path):
    """reference_vo is deterministic: its two trials on a real synthetic sequence give the same figures; stats
    counts them once and says which method that is, in text and JSON."""
    from slamrun.datasets.make_synthetic import generate
    from slamrun.engine.campaign import run_campaign
    from slamrun.engine.spec_file import load_spec
    from tests.conftest import write_spec

    data = tmp_path / "data"
    generate(data / "seq_a", frames=80, seed=3, size=(320, 240), layout="euroc")
    ds = [{"name": "e", "path": str(data), "sequences": ["seq_a"], "layout": "euroc"}]
    spec = write_spec(tmp_path, data, [{"name": "reference_vo"}], datasets=ds, directions=["forward"], trials=2)
    res = run_campaign(load_spec(spec), log=lambda *a: None)
    df = pd.read_csv(res.results_csv)
    assert (df.status == "done").all() and df.ate_rmse.nunique() == 1
    base = [sys.executable, "-m", "slamrun.cli", "stats", str(tmp_path / "results")]
    out = json.loads(subprocess.run([*base, "--json"], capture_output=True, text=True, check=True).stdout)
    block = out["datasets"]["e"]
    assert block["counted"]["reference_vo"] == {"runs": 2, "distinct": 1, "deterministic": True}
    text = subprocess.run(base, capture_output=True, text=True, check=True).stdout
    assert "reference_vo 1 of 2 (deterministic: identical trials)" in text
