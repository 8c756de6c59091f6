"""DPV-SLAM is DPVO with its proximity loop closure (`loop_closure: true`, DPVO's `--opts LOOP_CLOSURE True`): the
parameters reach DPVO's cfg, the image holds the modules the loop closure imports, pinned by hash, and adding the
parameters renamed none of the DPVO configurations that had runs before (their settings' hashes are unchanged)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import yaml
from pydantic import BaseModel, Field

from slamrun.engine.plan import hashed, settings_hash
from slamrun.engine.spec import MethodSpec
from slamrun.images import sources as src
from slamrun.images.build import pypi_files_of
from slamrun.methods.declare import added
from slamrun.methods.dpvo import Dpvo, DpvoParams
from slamrun.methods.dpvo import process as dpvo_process
from tests.conftest import recipe

ROOT = Path(__file__).resolve().parents[1]
TORCH_CUDA = recipe("torch_cuda")
LOOP = ("loop_closure", "backend_thresh", "max_edge_age", "global_opt_freq")


def test_dpv_slam_is_dpvo_with_its_loop_closure_and_the_authors_backend_settings():
    _, cfg = dpvo_process.config(Dpvo({"loop_closure": True}).settings())
    assert cfg.LOOP_CLOSURE is True and not cfg.CLASSIC_LOOP_CLOSURE
    assert (cfg.BACKEND_THRESH, cfg.MAX_EDGE_AGE, cfg.GLOBAL_OPT_FREQ) == (64.0, 1000, 15)  # dpvo/config.py's
    _, cfg = dpvo_process.config(Dpvo({"loop_closure": True, "global_opt_freq": 5}).settings())
    assert cfg.GLOBAL_OPT_FREQ == 5
    assert not dpvo_process.config(Dpvo().settings())[1].LOOP_CLOSURE  # DPVO as before


def test_the_dpvo_configurations_run_before_keep_their_settings_name():
    """The hashes of 1fcb01a, before the loop-closure parameters: default DPVO at campaign seed 0 and a stride-1 DPVO
    at seed 3. A run made then is resumed, not run again; DPV-SLAM is a configuration of its own."""
    assert settings_hash(MethodSpec(name="dpvo"), 0) == "b3e781f550"
    assert settings_hash(MethodSpec(name="dpvo", params={"stride": 1}), 3) == "6a25c362e7"
    slam = settings_hash(MethodSpec(name="dpvo", label="dpv_slam", params={"loop_closure": True}), 0)
    assert slam not in ("b3e781f550", settings_hash(MethodSpec(name="dpvo", params={"loop_closure": False}), 0))
    assert all("added" in (DpvoParams.model_fields[k].json_schema_extra or {}) for k in LOOP)


def test_an_added_parameter_is_left_out_of_the_name_only_at_its_default():
    class Params(BaseModel):
        old: int = 1
        new: bool = Field(False, json_schema_extra=added("2026-11-29"))

    assert hashed(Params, {"old": 1, "new": False}) == {"old": 1}
    assert hashed(Params, {"old": 2, "new": True}) == {"old": 2, "new": True}


def test_the_loop_closure_modules_are_in_the_torch_stage_pinned_by_hash():
    """numba (with llvmlite), pypose (with packaging), einops and scipy: what dpvo/loop_closure/optim_utils.py imports,
    copied and installed --no-deps from the generated requirements file, checked by the image's build."""
    table = src.pypi_table(src.DPVO_LOOP_CLOSURE)
    assert {f.project for f in table} == {"numba", "llvmlite", "pypose", "packaging", "einops", "scipy"}
    assert set(dpvo_process.LOOP_CLOSURE_MODULES) <= {f.project for f in table}
    assert all(src.PYPI_FILES[f.filename] == f for f in table)
    text = (TORCH_CUDA / "requirements-loop-closure.txt").read_text()
    lines = [line for line in text.splitlines() if not line.startswith("#")]
    assert "\n".join(lines) + "\n" == src.requirements(list(table))
    wheels = pypi_files_of(recipe("dpvo") / "Dockerfile")
    assert [f.filename for f in table] == wheels[-len(table) :]
    stages = (TORCH_CUDA / "stages.Dockerfile").read_text()
    assert re.search(r"--require-hashes --no-deps -r /opt/slamrun-build/requirements-loop-closure.txt", stages)
    check = (recipe("dpvo") / "check_image.py").read_text()
    assert "from dpvo.loop_closure.optim_utils import reduce_edges" in check


def test_gpu_check_runs_dpv_slam_beside_dpvo(tmp_path):
    """scripts/gpu-check.sh's campaign holds each published variant of its method (the declaration's, through
    `slamrun list-methods --json`) as one more method entry: dpvo's is dpv_slam, loop closure on."""
    script = (ROOT / "scripts" / "gpu-check.sh").read_text()
    start = script.index("variant_entries() {")
    function = script[start : script.index("\n}\n", start) + 3]
    bash = f"SLAMRUN=({sys.executable} -m slamrun.cli); PYTHON={sys.executable}; METHOD=dpvo\n{function}variant_entries"
    res = subprocess.run(["bash", "-c", bash], cwd=ROOT, capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    (entry,) = yaml.safe_load(res.stdout)
    assert entry == {"name": "dpvo", "label": "dpv_slam-standin", "params": {"loop_closure": True}}
    assert MethodSpec(**entry).run_label == "dpv_slam-standin" and DpvoParams(**entry["params"]).loop_closure
    assert Dpvo.variants == {"dpv_slam": {"loop_closure": True}}


def test_the_dpv_slam_config_runs_both_as_their_authors_evaluate_them():
    from slamrun.engine.spec_file import load_spec

    spec = load_spec(ROOT / "configs" / "dpv-slam.yaml", check_files=False, check_gpu=False)
    assert [(m.run_label, m.params) for m in spec.methods] == [("dpvo", {}), ("dpv_slam", {"loop_closure": True})]
    assert spec.trials == 5 and [d.value for d in spec.directions] == ["forward"]
    assert spec.datasets[0].layout == "euroc" and spec.datasets[0].metrics == ["ate"]
