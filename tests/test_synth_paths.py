"""Each synthetic sequence's camera loop follows its seed: two sequences of one spec are two motions (the demo's
two rooms too), each within the plain loop's motion, so what tracks the plain loop tracks them."""

from __future__ import annotations

import numpy as np
import pytest

from slamrun.datasets.make_synthetic import generate
from slamrun.datasets.synth import MOTION_SLACK, PathShape, Synth, camera_path, lap_length, path_motion, path_shape


def test_two_seeds_are_two_motions_written_in_their_files(tmp_path):
    """The demo's room_a and room_b (seeds 0 and 1): different ground truth, path length and turning sense or
    start, not only a different texture."""
    a = generate(tmp_path / "room_a", frames=40, seed=0, size=(64, 48))
    b = generate(tmp_path / "room_b", frames=40, seed=1, size=(64, 48))
    gt_a, gt_b = (np.loadtxt(s / "groundtruth_full.txt") for s in (a, b))
    assert gt_a.shape == gt_b.shape
    assert np.abs(gt_a[:, 1:4] - gt_b[:, 1:4]).max() > 0.3  # metres apart somewhere
    lengths = [lap_length(Synth(40, seed, (64, 48), "indoor", "x").scene) for seed in (0, 1)]
    assert abs(lengths[0] - lengths[1]) > 0.05


def test_every_seed_differs_and_stays_within_the_plain_loops_motion():
    plain = path_motion(PathShape.plain())
    shapes = [path_shape("indoor", seed) for seed in range(40)]
    assert len({(s.radii, s.start, s.turn) for s in shapes}) == 40
    assert {s.turn for s in shapes} == {1, -1}
    assert {s.bob[0] for s in shapes} == {2, 3, 4}
    lengths = [lap_length(Synth(10, seed, (64, 48), "indoor", "x").scene) for seed in range(40)]
    assert max(lengths) - min(lengths) > 1.0  # metres: the loops' lengths spread
    for seed, shape in enumerate(shapes):
        speed, turning = path_motion(shape)
        assert speed <= plain[0] * MOTION_SLACK * 1.001 and turning <= plain[1] * MOTION_SLACK * 1.001, seed
        assert min(shape.radii) >= 1.9 - 1e-9, seed  # never nearer the boxes than the plain loop
        assert 1.1 < shape.height < 1.5 and abs(shape.surge) < 0.2


@pytest.mark.parametrize("seed", [0, 1, 7])
def test_a_seeds_loop_closes_and_keeps_the_boxes_in_view(seed):
    """Start and end see the same place (a loop to close) and the camera always looks at the boxes' middle."""
    s = Synth(200, seed, (64, 48), "indoor", "x")
    rots, pos = camera_path(s.scene, 200)
    assert np.allclose(pos[0], pos[-1], atol=1e-9) and np.allclose(rots[0], rots[-1], atol=1e-9)
    to_middle = s.scene.look_at - pos
    to_middle /= np.linalg.norm(to_middle, axis=1, keepdims=True)
    cos = np.einsum("ni,ni->n", rots[:, :, 2], to_middle)  # the optical axis against the way to the middle
    assert np.degrees(np.arccos(cos.min())) < 15
    room = s.scene
    assert (pos > room.room_lo + 1.0).all() and (pos < room.room_hi - 1.0).all()


def test_the_plain_loop_is_the_one_every_sequence_had_before():
    """PathShape.plain(): radii 2.3 and 1.9 m at 1.3 m, anticlockwise from +x; a scene made without a path has it."""
    from slamrun.datasets.synth import make_scene

    scene = make_scene("indoor", np.random.default_rng(0))
    assert scene.path == PathShape.plain()
    rots, pos = camera_path(scene, 5)
    assert np.allclose(pos[:, :2], [[2.3, 0], [0, 1.9], [-2.3, 0], [0, -1.9], [2.3, 0]], atol=1e-9)
