"""A real upstream method through the Docker backend: DSO built from the pinned source archive (shared/upstream)
when its image is missing, then run forward and backward on a synthetic sequence by a campaign.

Skips without shared/upstream or a Docker engine; under CI (CI=true) a missing engine fails, as in
test_docker.py. The first build takes about 10-25 minutes on 2 cores; Docker's cache keeps it.
"""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest

from runner.datasets.synth import generate
from runner.engine.campaign import run_campaign
from runner.engine.spec import load_spec
from runner.images.build import BuildOptions, build
from runner.images.verify import scene_extent
from tests.conftest import UPSTREAM, require_upstream, write_spec
from tests.test_docker import engine_with_base


@pytest.fixture(scope="module")
def dso_image():
    require_upstream()
    engine_with_base()
    build(["dso"], log=lambda m: None, opts=BuildOptions(sources_dir=UPSTREAM), only_missing=True)
    return "slamrun/dso:latest"


def test_real_dso_forward_and_backward_through_docker(dso_image, tmp_path):
    data = tmp_path / "data"
    generate(data / "room", frames=200, seed=3)
    spec = write_spec(
        tmp_path,
        data,
        [{"name": "dso"}],
        datasets=[{"name": "synth", "path": str(data), "sequences": ["room"]}],
        backend="docker",
        lanes=1,
        timeout_s=600,
    )
    res = run_campaign(load_spec(spec), log=lambda *a: None)
    df = pd.read_csv(res.results_csv)
    assert res.counts["done"] == 2, df[["direction", "status", "failure", "message"]].to_string()
    assert set(df.direction) == {"forward", "backward"} and (df.eval_status == "ok").all()
    extent = scene_extent(data / "room")
    assert (df.e_align / extent < 0.02).all(), df[["direction", "e_align"]].to_string()
    assert (df.n_poses > 20).all() and df.ram_peak_mb.notna().all() and (df.fps > 0).all()
    record = json.loads((Path(df.run_dir[0]) / "run.json").read_text())
    assert "JakobEngel/dso@7b0c99f01d238f801c625beaff90240bcb007198" in record["image"]["sources"]
    images = json.loads((res.results / "images.json").read_text())  # beside the results too
    assert images["dso"]["id"] == record["image"]["id"] and images["dso"]["march"] == "x86-64-v2"
