"""KITTI's synthetic drive: at the default frame count long enough for KITTI's 100 m segments (its default metric
once never had a value on synthetic data: a 66 m loop whatever the frame count), and a report whose default metric
has no value says why."""

from __future__ import annotations

import numpy as np
import pandas as pd

from slamrun.datasets.kitti import drive
from slamrun.datasets.make_synthetic import generate
from slamrun.datasets.synth import Synth, lap_length


def test_the_drive_grows_with_the_frames_and_never_faster_than_a_lap_per_100_frames():
    for seed in range(6):  # each seed's courtyard loop is its own (57-80 m)
        for frames in (60, 150, 200, 300, 1000):
            s = drive(Synth(frames, seed, (160, 120), "indoor", "00"))
            lap = lap_length(s.scene)
            assert s.scene_kind == "outdoor" and 55 < lap < 80, (seed, frames)
            assert 1 <= s.laps <= max(1, frames // 100), (seed, frames)
            if frames >= 200:
                assert s.laps * lap >= 100, (seed, frames)  # KITTI's shortest segment fits
            else:
                assert s.laps == 1


def test_kittis_synthetic_drive_has_segments_at_the_default_frame_count(tmp_path):
    """300 frames (SynthSpec's default): two or three laps of the courtyard, 120 m or more, so KITTI's default
    metric gets a finite value through a real campaign; 60 frames drive one lap (under 100 m): no segment, and the
    report says so in one line instead of dropping the column silently."""
    from slamrun.analysis.report import write_report
    from slamrun.engine.campaign import run_campaign
    from slamrun.engine.spec_file import load_spec
    from tests.conftest import fake_method, write_spec

    data = tmp_path / "dataset" / "sequences"
    generate(data / "00", frames=300, seed=0, size=(160, 120), layout="kitti")
    generate(data / "01", frames=60, seed=1, size=(160, 120), layout="kitti")
    poses = np.loadtxt(tmp_path / "dataset" / "poses" / "00.txt")
    travelled = np.linalg.norm(np.diff(poses[:, [3, 7, 11]], axis=0), axis=1).sum()
    assert 120 < travelled < 2 * 80  # two laps of the courtyard (57-80 m each, by seed)
    datasets = [
        {"name": "long", "path": str(data), "sequences": ["00"], "layout": "kitti"},
        {"name": "short", "path": str(data), "sequences": ["01"], "layout": "kitti"},
    ]
    spec = write_spec(tmp_path, data, [fake_method(extra=["--noise", "0.05"])], datasets=datasets)
    res = run_campaign(load_spec(spec), log=lambda *a: None)
    df = pd.read_csv(res.results_csv)
    long, short = df[df.dataset == "long"], df[df.dataset == "short"]
    assert (long.status == "done").all() and np.isfinite(long.kitti_t_pct).all() and (long.kitti_t_pct > 0).all()
    assert (short.status == "done").all() and short.kitti_t_pct.isna().all()
    html = write_report(res.results).read_text()
    assert "KITTI&#x27;s segment errors: no value in this dataset&#x27;s 2 done run(s)" in html
    assert "shorter than 100 m: no segment" in html
