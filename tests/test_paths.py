"""A run's path as the report's and the live page's views draw it: aligned exactly as its metric aligned it, so the
drawn distance to the ground truth is the figure the tables give."""

from __future__ import annotations

import json

import numpy as np
import pytest

from slamrun.analysis.paths import aligned
from slamrun.core import metrics
from slamrun.core.evaluation import ASSOCIATION_TOLERANCE_S
from slamrun.core.formats import read_trajectory


@pytest.mark.parametrize("alignment", ["sim3", "se3", "first:50"])
def test_a_path_is_drawn_as_its_ate_aligned_it(shared_data, alignment):
    """Real ORB-SLAM (monocular) on fr2_desk: with se3 (no scale) the drawn path was a Sim(3)'s, 0.02 m from the
    ground truth where the ATE the tables give is the se3 fit's."""
    evo = shared_data / "evo_test_data"
    gt = read_trajectory(evo / "fr2_desk_groundtruth.txt", "tum")
    est = read_trajectory(evo / "fr2_desk_ORB.txt", "tum")
    ate = metrics.ate(gt, est, alignment, ASSOCIATION_TOLERANCE_S)  # as a campaign's evaluation computes it
    drawn = aligned(est, gt, "ate_rmse", alignment)
    pairs = metrics.associate(gt, est, ASSOCIATION_TOLERANCE_S)
    rows = np.searchsorted(est.timestamps, pairs.est.timestamps)
    rmse = float(np.sqrt(np.mean(np.sum((drawn[rows] - pairs.gt.positions) ** 2, axis=1))))
    assert rmse == pytest.approx(ate.translation.rmse, rel=1e-9)


@pytest.mark.parametrize(
    ("alignment", "said"),
    [
        ("sim3", "aligned by a Sim(3) over all poses (ATE)"),
        ("se3", "aligned by an SE(3) over all poses (ATE)"),
        ("first:50", "aligned by a Sim(3) over the first 50 poses (ATE)"),
        ("none", "not aligned (ATE without alignment)"),
    ],
)
def test_a_views_caption_says_the_alignment_the_campaign_used(alignment, said):
    from slamrun.analysis.paths import SequencePaths, run_alignment

    settings = json.dumps({"alignment": alignment, "metrics": ["ate"]})
    paths = SequencePaths("s", "ate_rmse", "m", "euroc", np.zeros((3, 3)), None, [], run_alignment(settings))
    assert paths.aligned_by() == said
    assert run_alignment(None) == run_alignment("not json") == "sim3"


def test_a_path_that_cannot_be_aligned_says_why(shared_data):
    """A first:N longer than the run: the live page said "under three of its poses meet the ground truth" where
    every pose met it; the reason is the alignment's."""
    from slamrun.errors import MetricError

    evo = shared_data / "evo_test_data"
    gt = read_trajectory(evo / "fr2_desk_groundtruth.txt", "tum")
    est = read_trajectory(evo / "fr2_desk_ORB.txt", "tum")
    with pytest.raises(MetricError, match="first 100000 poses, but 1204 pair"):
        aligned(est, gt, "ate_rmse", "first:100000")
    far = type(est)(est.timestamps + 1e6, est.positions, est.quaternions)
    with pytest.raises(MetricError, match="0 of its poses meet the start segment"):
        aligned(far, gt, "e_align")
