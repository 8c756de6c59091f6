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

from slamrun.datasets.make_synthetic import generate
from slamrun.engine.campaign import run_campaign
from slamrun.engine.spec_file import load_spec
from slamrun.images.build import BuildOptions, build
from slamrun.images.verify import scene_extent
from tests.conftest import UPSTREAM, require_upstream, write_spec
from tests.test_docker import IN_CI, engine_with_base


@pytest.fixture(scope="module")
def dso_image():
    require_upstream()
    engine_with_base()
    build(["dso"], log=lambda m: None, opts=BuildOptions(sources_dir=UPSTREAM), only_missing=True)
    return "slamrun/dso:latest"


def dso_campaign(root: Path, data: Path, backend: str) -> pd.DataFrame:
    """Single-threaded DSO (nomt=1: repeatable, so two engines cannot differ by their timing) on the room of `data`,
    forward and backward, one trial each, through `backend`: its results, every run asserted done."""
    root.mkdir()
    spec = write_spec(
        root,
        data,
        [{"name": "dso", "params": {"single_thread": True}}],
        datasets=[{"name": "synth", "path": str(data), "sequences": ["room_a"]}],
        backend=backend,
        trials=1,
        lanes=2,
        timeout_s=600,
        name=f"dso-{backend}",
    )
    res = run_campaign(load_spec(spec), log=lambda *a: None)
    df = pd.read_csv(res.results_csv)
    assert res.counts["done"] == 2, df[["sequence", "direction", "status", "failure", "message"]].to_string()
    return df.assign(results=str(res.results))


@pytest.fixture(scope="module")
def dso_docker(dso_image, tmp_path_factory):
    """One Docker campaign of DSO, shared by the tests that read it (CI runs it once): (its results, the room)."""
    data = tmp_path_factory.mktemp("dso-rooms")
    generate(data / "room_a", frames=200, seed=3)
    return dso_campaign(data.parent / f"{data.name}-docker", data, "docker"), data


def test_real_dso_forward_and_backward_through_docker(dso_docker):
    df, data = dso_docker
    assert set(df.direction) == {"forward", "backward"} and (df.eval_status == "ok").all()
    assert (df.e_align / scene_extent(data / "room_a") < 0.02).all(), df[["direction", "e_align"]].to_string()
    assert (df.n_poses > 20).all() and df.ram_peak_mb.notna().all() and (df.fps > 0).all()
    record = json.loads((Path(df.run_dir[0]) / "run.json").read_text())
    assert "JakobEngel/dso@7b0c99f01d238f801c625beaff90240bcb007198" in record["image"]["sources"]
    images = json.loads((Path(df.results[0]) / "images.json").read_text())  # beside the results too
    assert images["dso"]["id"] == record["image"]["id"] and images["dso"]["march"] == "x86-64-v2"


def test_real_dso_on_a_perturbed_view_through_docker(dso_docker, tmp_path):
    """Issue 53: DSO's image reads a perturbed view (noisy frames, PNG where the baseline view holds the
    originals) as it reads any view: forward on the same room, beside its baseline run, in parallel lanes."""
    _, data = dso_docker
    spec = write_spec(
        tmp_path,
        data,
        [{"name": "dso", "params": {"single_thread": True}}],
        datasets=[{"name": "synth", "path": str(data), "sequences": ["room_a"]}],
        directions=["forward"],
        perturbations=[{"kind": "gaussian_noise", "sigma": [3]}],
        backend="docker",
        trials=1,
        lanes=2,
        timeout_s=600,
        name="dso-perturbed",
    )
    res = run_campaign(load_spec(spec), log=lambda *a: None)
    df = pd.read_csv(res.results_csv)
    assert res.counts["done"] == 2, df[["perturbation", "status", "failure", "message"]].to_string()
    noisy = df[df.perturbation == "gaussian_noise"].iloc[0]
    assert noisy.level == 3 and noisy.eval_status == "ok" and noisy.n_poses > 20
    assert noisy.e_align / scene_extent(data / "room_a") < 0.05, noisy.e_align
    record = json.loads((Path(noisy.run_dir) / "run.json").read_text())
    assert "/forward+gaussian_noise-3/" in noisy.run_dir and "-gaussian_noise-3-" in Path(record["view"]).name
    assert json.loads((Path(record["view"]) / "view.json").read_text())["perturbation"] == "gaussian_noise-3"


def path_length(positions) -> float:
    import numpy as np

    finite = positions[np.isfinite(positions).all(axis=1)]
    return float(np.linalg.norm(np.diff(finite, axis=0), axis=1).sum())


def test_real_dso_on_the_euroc_and_kitti_layouts_through_docker(dso_image, tmp_path):
    """DSO (without photometric calibration: mode=1) on a synthetic EuRoC sequence (rectified from its
    radial-tangential camera) and a KITTI one (pinhole, poses without timestamps), forward: every run done, ATE
    under 2 % of the path's length. (Backward views of every layout are tested with reference_vo in
    test_dataset_layouts.py, and DSO backward through Docker above: a view is the same whoever runs it.)"""
    from slamrun.datasets.layouts import open_sequence

    euroc = generate(tmp_path / "euroc" / "V1_synth", frames=200, seed=5, layout="euroc")
    kitti = generate(tmp_path / "kitti" / "sequences" / "07", frames=200, seed=6, layout="kitti")
    datasets = [
        {"name": "euroc", "layout": "euroc", "path": str(euroc.parent), "sequences": [euroc.name]},
        {"name": "kitti", "layout": "kitti", "path": str(kitti.parent), "sequences": [kitti.name]},
    ]
    spec = write_spec(
        tmp_path,
        tmp_path,
        [{"name": "dso", "directions": ["forward"]}],
        datasets=datasets,
        backend="docker",
        lanes=1,
        timeout_s=600,
    )
    res = run_campaign(load_spec(spec), log=lambda *a: None)
    df = pd.read_csv(res.results_csv)
    assert res.counts["done"] == 2, df[["dataset", "direction", "status", "failure", "message"]].to_string()
    assert (df.eval_status == "ok").all() and df.ate_rmse.notna().all()
    for name, folder in (("euroc", euroc), ("kitti", kitti)):
        length = path_length(open_sequence(folder).groundtruth().positions)
        runs = df[df.dataset == name]
        assert (runs.ate_rmse / length < 0.02).all(), (name, length, runs[["direction", "ate_rmse"]].to_string())
    for run_dir in df.run_dir:  # no photometric calibration in these datasets: DSO's mode=1, no gamma/vignette
        argv = json.loads((Path(run_dir) / "run.json").read_text())["argv"]
        assert "mode=1" in argv and not any(a.startswith(("gamma=", "vignette=")) for a in argv), argv


def test_real_dso_through_podman_matches_docker(dso_docker, tmp_path):
    """The same DSO image run by podman (no daemon; loaded from `slamrun images --export`'s archive) and by
    Docker (the shared campaign): room_a forward and backward, one trial each, every run done, e_align medians within
    10 %. DSO runs single-threaded (nomt=1, repeatable), so the engines' timing cannot make the two differ;
    multi-threaded, two campaigns of 8 runs differ by ~15 % in their medians on the same engine."""
    import shutil

    from tests.test_docker import in_podman

    if shutil.which("podman") is None:
        if IN_CI:
            pytest.fail("podman is not installed (.ci/run installs it)")
        pytest.skip(reason="podman is not installed (apt-get install podman; .ci/run installs it)")
    docker, data = dso_docker
    in_podman("slamrun/dso:latest")
    podman = dso_campaign(tmp_path / "podman", data, "podman")
    assert (podman.eval_status == "ok").all() and podman.ram_peak_mb.notna().all() and (podman.fps > 0).all()
    medians = {"docker": float(docker.e_align.median()), "podman": float(podman.e_align.median())}
    assert abs(medians["podman"] - medians["docker"]) <= 0.10 * medians["docker"], medians
