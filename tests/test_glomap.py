"""glomap: GLOMAP's global SfM through pycolmap, typed parameters, and a short real run forward and backward."""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from pydantic import ValidationError

import slamrun.methods
from slamrun.core.trajectory import read_tum
from slamrun.datasets.make_synthetic import generate
from slamrun.engine.campaign import run_campaign
from slamrun.engine.spec_file import load_spec
from slamrun.images.verify import scene_extent
from tests.conftest import one_sequence, write_spec

ROOT = Path(__file__).resolve().parents[1]


def test_glomap_is_a_native_method_with_typed_parameters(tmp_path):
    from slamrun.datasets.view import Profile
    from tests.test_methods import make_view

    cls = slamrun.methods.get("glomap")
    assert cls.native and cls.image is None and cls.profile is slamrun.methods.get("colmap").profile
    with pytest.raises(ValidationError):
        cls({"stride": 0})
    with pytest.raises(ValidationError):
        cls({"ba_iterations": "many"})
    with pytest.raises(ValidationError, match="extra"):
        cls({"mapper": "incremental"})  # glomap is the global mapper; colmap is the incremental one
    view = make_view(tmp_path / "v", 1000.0 + np.arange(20) / 30.0, Profile.rectified)
    argv = cls({"stride": 2, "min_num_matches": 30}).command(view, tmp_path / "work")
    assert argv[1:5] == ["-m", "slamrun.methods.sfm_process", "--mapper", "global"]
    assert argv[argv.index("--stride") + 1] == "2" and argv[argv.index("--min-num-matches") + 1] == "30"
    assert argv[argv.index("--out") + 1] == str(tmp_path / "work" / "trajectory.txt")


def test_the_pinned_pycolmap_has_global_mapping():
    import pycolmap

    major, minor = (int(x) for x in pycolmap.__version__.split(".")[:2])
    assert (major, minor) >= (4, 2) and major < 5  # pyproject.toml's range
    assert callable(pycolmap.global_mapping) and hasattr(pycolmap.GlobalPipelineOptions(), "mapper")
    assert '"pycolmap>=4.2,<5"' in (ROOT / "pyproject.toml").read_text()


def first_frames(sequence: Path, n: int) -> None:
    """Keep the first `n` frames of a synthetic TUM-Mono sequence (times, both ground truths, images)."""
    for name in ("times.txt", "groundtruthSync.txt", "groundtruth_full.txt"):
        path = sequence / name
        path.write_text("".join(path.read_text().splitlines(keepends=True)[:n]))
    with zipfile.ZipFile(sequence / "images.zip") as zf:
        kept = {m: zf.read(m) for m in sorted(zf.namelist())[:n]}
    with zipfile.ZipFile(sequence / "images.zip", "w") as zf:
        for m, data in kept.items():
            zf.writestr(m, data)


def test_glomap_forward_and_backward_on_a_short_room(tmp_path):
    """A real global reconstruction (the first 100 frames of a room, every 3rd: 34 images a run): both directions
    done and evaluated, every pose at a frame's original time, ATE under 5 % of the path's extent (the verification
    table's bound). The room's loop is cut rather than rendered in fewer frames: with 90 frames for the whole loop
    (0.45 m between the images used) global positioning breaks the chain (ATE 10 % of the extent, measured)."""
    data = tmp_path / "data"
    generate(data / "seq_a", frames=300, seed=3, size=(640, 480))
    first_frames(data / "seq_a", 100)
    params = {"stride": 3, "max_features": 600, "overlap": 6, "max_image_size": 480}
    datasets = [{**one_sequence(data)[0], "metrics": ["tum-mono", "ate"]}]
    spec = write_spec(tmp_path, data, [{"name": "glomap", "params": params}], datasets=datasets, timeout_s=300)
    res = run_campaign(load_spec(spec), log=lambda *a: None)
    df = pd.read_csv(res.results_csv)
    assert len(df) == 2 and (df.status == "done").all() and (df.eval_status == "ok").all(), df.message.tolist()
    assert set(df.direction) == {"forward", "backward"} and (df.n_poses >= 30).all()
    extent = scene_extent(data / "seq_a")
    assert (df.ate_rmse / extent < 0.05).all(), (df.ate_rmse / extent).tolist()
    frames = np.loadtxt(data / "seq_a" / "times.txt")[:, 1]
    for run_dir in df.run_dir:
        t = read_tum(Path(run_dir) / "trajectory.txt").timestamps
        assert np.isin(np.round(t, 6), np.round(frames, 6)).all()


def test_the_example_spec_runs_glomap_beside_colmap_natively():
    from slamrun.engine.plan import plan

    spec = load_spec(ROOT / "configs" / "glomap.yaml", check_files=False)
    assert spec.backend == "local" and [m.name for m in spec.methods] == ["glomap", "colmap"]
    assert spec.datasets[0].metrics == ["tum-mono", "ate"] and len(plan(spec)) == 16
