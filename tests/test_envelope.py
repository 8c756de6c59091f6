"""The motion envelope of the synthetic paths (datasets/envelope.py): every default path stays inside the envelope of
the plain loop the earlier rooms had (fastest speed and rotation rate at most MOTION_SLACK above it, the parallax of
the first 10 and 20 frames at least its own over MOTION_SLACK), `motion` leaves it on purpose, and the figures of
real ground truth (KITTI, EuRoC, TUM RGB-D) come out of the same functions."""

from __future__ import annotations

import json
import subprocess
import sys
from typing import get_args

import numpy as np
import pytest

from slamrun.core.formats import read_trajectory
from slamrun.core.trajectory import read_kitti
from slamrun.datasets.envelope import at_frame_rate, motion_envelope, synthetic_envelope
from slamrun.datasets.generated import SYNTH_MARKER
from slamrun.datasets.make_synthetic import generate
from slamrun.datasets.synth import MOTION_SLACK, MOTIONS, PathShape, path_shape
from slamrun.engine.spec import Motion, SynthSpec

SEEDS = range(50)


@pytest.fixture(scope="module")
def plain():
    return {frames: synthetic_envelope(seed=None, frames=frames) for frames in (300, 400)}


def test_the_plain_loops_envelope(plain):
    """The earlier rooms' loop at the default 300 frames (30 fps): the figures the README states."""
    e = plain[300]
    assert e.speed_max == pytest.approx(0.0483, abs=1e-4) and e.speed_max_s == pytest.approx(1.45, abs=0.01)
    assert e.speed_median == pytest.approx(0.0446, abs=1e-4)
    assert e.rotation_max == pytest.approx(1.92, abs=0.01) and e.rotation_median == pytest.approx(1.15, abs=0.01)
    assert e.depth == pytest.approx(2.38, abs=0.01)
    assert e.start_translation[10] == pytest.approx(0.404, abs=1e-3)
    assert e.start_parallax(10) == pytest.approx(0.170, abs=1e-3) and e.start_parallax(20) == pytest.approx(
        0.339, abs=1e-3
    )
    assert e.start_rotation[10] == pytest.approx(10.1, abs=0.1)
    # one loop a sequence: per frame the motion scales with 1 / frames, per second not at all per loop length
    assert plain[400].speed_max == pytest.approx(e.speed_max * 299 / 399, rel=2e-3)


@pytest.mark.parametrize("frames", [300, 400])
@pytest.mark.parametrize("kind", ["indoor", "outdoor"])
def test_every_default_path_stays_inside_the_earlier_envelope(plain, frames, kind):
    """Seeds 0-49 (the demo's and verification's rooms are seeds 0 and 1): at most 10 % (MOTION_SLACK) faster and
    turning faster than the plain loop at its fastest, and at least its start's parallax over 1.1, both ways."""
    ref = plain[frames] if kind == "indoor" else synthetic_envelope("outdoor", None, frames)
    for seed in SEEDS if kind == "indoor" else range(10):
        e = synthetic_envelope(kind, seed, frames)
        assert e.speed_max <= ref.speed_max * MOTION_SLACK * 1.001, seed
        assert e.rotation_max <= ref.rotation_max * MOTION_SLACK * 1.001, seed
        for k in (10, 20):
            assert e.start_parallax(k) >= ref.start_parallax(k) / MOTION_SLACK * 0.999, (seed, k)


def test_motion_plain_is_the_earlier_loop_and_hard_leaves_the_envelope(plain):
    assert all(path_shape("indoor", seed, "plain") == PathShape.plain() for seed in (0, 1, 8))
    assert path_shape("outdoor", 3, "plain") == PathShape.plain(5.0)
    hard = [synthetic_envelope(seed=seed, motion="hard") for seed in range(20)]
    ref = plain[300]
    assert max(e.speed_max for e in hard) > 1.3 * ref.speed_max
    assert max(e.rotation_max for e in hard) > 1.5 * ref.rotation_max
    assert min(e.start_parallax(10) for e in hard) < 0.8 * ref.start_parallax(10)
    with pytest.raises(ValueError, match="motion 'fast'"):
        path_shape("indoor", 0, "fast")


def test_a_written_sequences_ground_truth_gives_its_paths_envelope(tmp_path):
    """The envelope read back from a generated sequence's groundtruth_full.txt is the path's."""
    seq = generate(tmp_path / "room", frames=40, seed=1, size=(64, 48))
    gt = read_trajectory(seq / "groundtruth_full.txt")
    from_file = motion_envelope(gt.timestamps, gt.positions, gt.rotations())
    expected = synthetic_envelope(seed=1, frames=40)
    assert from_file.fps == pytest.approx(30.0, rel=1e-3)
    assert from_file.speed_max == pytest.approx(expected.speed_max, rel=1e-5)
    assert from_file.rotation_max == pytest.approx(expected.rotation_max, abs=1e-4)
    assert from_file.start_translation[10] == pytest.approx(expected.start_translation[10], rel=1e-5)
    plain_seq = generate(tmp_path / "plain", frames=40, seed=1, size=(64, 48), motion="plain")
    gt_plain = read_trajectory(plain_seq / "groundtruth_full.txt")
    assert np.allclose(gt_plain.positions[0], [2.3, 0.0, 1.3])  # the plain loop starts on its long axis
    assert '"motion": "plain"' in (plain_seq / ".slamrun-synth.json").read_text()
    assert "motion" not in (seq / ".slamrun-synth.json").read_text()


def test_a_circle_at_known_speed():
    """A camera circling at 1 m/s on a 2 m radius, sampled at 100 Hz, taken at 20 fps: 0.05 m and 1.43 degrees a
    frame; a gap in the samples is left out, not bridged."""
    t = np.arange(0, 10, 0.01)
    a = t / 2.0
    pos = np.column_stack([2 * np.cos(a), 2 * np.sin(a), np.zeros_like(a)])
    rots = np.array([[[np.cos(x), -np.sin(x), 0], [np.sin(x), np.cos(x), 0], [0, 0, 1]] for x in a])
    e = motion_envelope(t, pos, rots, depth=2.0, fps=20.0)
    assert e.frames == 200 and e.fps == 20.0
    assert e.speed_median == pytest.approx(0.05, rel=1e-3) and e.speed_max_s == pytest.approx(1.0, rel=1e-3)
    assert e.rotation_max == pytest.approx(np.degrees(0.025), rel=1e-3)
    assert e.start_parallax(10) == pytest.approx(2 * 2 * np.sin(0.125) / 2.0, rel=1e-6)
    keep = (t < 4) | (t > 6)
    times, p, _ = at_frame_rate(t[keep], pos[keep], rots[keep], 20.0)
    assert np.isnan(p[(times > 4.03) & (times < 5.97)]).all() and np.isfinite(p[times < 4]).all()
    gapped = motion_envelope(t[keep], pos[keep], rots[keep], depth=2.0, fps=20.0)
    assert gapped.speed_max == pytest.approx(0.05, rel=1e-3)


def test_real_ground_truths_envelopes(shared_data):
    """KITTI 00 (10 Hz), EuRoC V1_02 (200 Hz ground truth, 20 Hz camera) and TUM RGB-D fr1/xyz and fr2/desk (100 Hz,
    30 Hz camera): each its own motion, figures the README's table holds."""
    d = shared_data / "evo_test_data"
    kitti = read_kitti(d / "KITTI_00_gt.txt", np.loadtxt(d / "KITTI_00_gt_times.txt"))
    k = motion_envelope(kitti.timestamps, kitti.positions, kitti.rotations())
    assert k.fps == pytest.approx(9.65, abs=0.01)  # its times.txt: 0.1036 s a frame
    assert 0.8 < k.speed_median < 0.9 and 1.3 < k.speed_max < 1.4  # m/frame: a car at 8-13 m/s
    assert k.rotation_median < 0.5 and 4 < k.rotation_max < 5
    euroc = read_trajectory(d / "V102_groundtruth.csv")
    e = motion_envelope(euroc.timestamps, euroc.positions, euroc.rotations(), fps=20.0)
    assert 0.04 < e.speed_median < 0.05 and 1.4 < e.rotation_median < 1.6 and 6 < e.rotation_max < 7
    assert e.start_translation[20] < 0.01  # the MAV stands still at the start
    for name, speed in (("freiburg1_xyz-groundtruth.txt", 0.0107), ("fr2_desk_groundtruth.txt", 0.0070)):
        g = read_trajectory(d / name)
        r = motion_envelope(g.timestamps, g.positions, g.rotations(), fps=30.0)
        assert r.speed_median == pytest.approx(speed, abs=5e-4) and r.speed_max < 0.03, name  # gaps not bridged


def test_motion_is_offered_by_the_spec_and_the_command_line_as_the_generator_has_it(tmp_path):
    """`synthetic: {motion: hard}` and `slamrun synth --motion hard` reach the generator; the names are its."""
    assert set(get_args(Motion)) == set(MOTIONS)
    assert SynthSpec(motion="hard").motion == "hard"
    with pytest.raises(ValueError):
        SynthSpec(motion="fast")
    out = tmp_path / "s"
    cmd = [sys.executable, "-m", "slamrun.cli", "synth", str(out), "--frames", "30", "--size", "64x48"]
    done = subprocess.run([*cmd, "--motion", "hard"], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert json.loads((out / SYNTH_MARKER).read_text())["motion"] == "hard"
