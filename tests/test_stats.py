"""The statistics reproduce R's numbers (shared/data/stats_golden) and the letter display's meaning."""

import itertools
import json

import numpy as np
import pandas as pd
import pytest

from slamrun.analysis.stats import adjust_p, compact_letters, study_statistics

METRICS = ["e_t", "e_r", "e_s", "e_start", "e_end", "e_rmse"]


@pytest.fixture(scope="module")
def golden(shared_data):
    obs = pd.read_csv(shared_data / "stats_golden" / "observations.csv")
    ref = json.loads((shared_data / "stats_golden" / "r_reference.json").read_text())
    return obs, ref, study_statistics(obs, METRICS)


def close(a, b):
    assert a == pytest.approx(b, rel=1e-9, abs=1e-300)


def test_mahalanobis_and_cutoff(golden):
    _, ref, ours = golden
    np.testing.assert_allclose(ours.mahalanobis, ref["mahalanobis"], rtol=1e-9)
    close(ours.cutoff, ref["cutoff"])
    assert ours.n_outliers == ref["n_outliers"]


@pytest.mark.parametrize("metric", METRICS)
def test_every_number_per_metric(golden, metric):
    _, ref, ours = golden
    r, m = ref["metrics"][metric], ours.metrics[metric]
    for g, v in r["medians"].items():
        close(m.medians[g], v)
    for g, v in r["lilliefors_p"].items():
        close(m.lilliefors_p[g], v)
    close(m.levene_F, r["levene_F"])
    close(m.levene_p, r["levene_p"])
    close(m.kruskal_chi2, r["kruskal_chi2"])
    assert m.kruskal_df == r["kruskal_df"]
    close(m.kruskal_p, r["kruskal_p"])
    for key in ("pairwise_holm", "pairwise_none"):
        ours_p = {frozenset((x["a"], x["b"])): x["p"] for x in getattr(m, key)}
        assert len(ours_p) == len(r[key])
        for x in r[key]:
            close(ours_p[frozenset((x["a"], x["b"]))], x["p"])
    assert _partition(m.letters) == _partition(r["letters"])


def _partition(letters: dict[str, str]) -> set[frozenset]:
    """Letters up to renaming: the set of groups that carry each letter."""
    chars = set("".join(letters.values()))
    return {frozenset(g for g, s in letters.items() if c in s) for c in chars}


def test_letters_share_exactly_when_not_significant():
    rng = np.random.default_rng(0)
    groups = [f"g{i}" for i in range(7)]
    for _ in range(200):
        p = {frozenset(pair): float(rng.choice([0.001, 0.5])) for pair in itertools.combinations(groups, 2)}
        letters = compact_letters(groups, p, alpha=0.05)
        for a, b in itertools.combinations(groups, 2):
            share = bool(set(letters[a]) & set(letters[b]))
            assert share == (p[frozenset((a, b))] > 0.05), (a, b, letters)


def test_p_adjust_matches_r_examples():
    # p.adjust(c(0.01, 0.02, 0.03, 0.04, 0.05), "holm") and "BH" in R
    p = np.array([0.01, 0.02, 0.03, 0.04, 0.05])
    np.testing.assert_allclose(adjust_p(p, "holm"), [0.05, 0.08, 0.09, 0.09, 0.09])
    np.testing.assert_allclose(adjust_p(p, "BH"), [0.05, 0.05, 0.05, 0.05, 0.05])
    np.testing.assert_allclose(adjust_p(p, "bonferroni"), [0.05, 0.1, 0.15, 0.2, 0.25])
    np.testing.assert_allclose(adjust_p(p, "none"), p)
