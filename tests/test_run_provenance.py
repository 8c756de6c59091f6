"""Every figure traceable to what produced it: each run records the machine that ran it (name, CPU, GPUs, Slurm's
node) and, for a native method, the Python packages it ran on; the report's provenance shows both; and a resume
with nothing left to run keeps the campaign's span (status and the report once said 0 s)."""

from __future__ import annotations

import json
import os
import platform
from importlib.metadata import version

import pandas as pd
import pytest

from slamrun.datasets.make_synthetic import generate
from slamrun.engine.campaign import run_campaign
from slamrun.engine.spec_file import load_spec
from tests.conftest import write_spec


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    root = tmp_path_factory.mktemp("provenance")
    data = root / "data"
    generate(data / "seq_a", frames=80, seed=3, size=(320, 240), layout="euroc")
    ds = [{"name": "e", "path": str(data), "sequences": ["seq_a"], "layout": "euroc"}]
    spec = write_spec(root, data, [{"name": "reference_vo"}], datasets=ds, directions=["forward", "backward"])
    res = run_campaign(load_spec(spec), log=lambda *a: None)
    return spec, res


def test_each_run_records_its_machine_and_packages(campaign):
    _, res = campaign
    df = pd.read_csv(res.results_csv)
    assert (df.status == "done").all() and (df.host == platform.node()).all()
    expected = f"numpy {version('numpy')}"
    assert df.packages.str.contains(expected, regex=False).all() and df.packages.str.contains("scipy").all()
    for run_dir in df.run_dir:
        record = json.loads((res.results / run_dir / "run.json").read_text())
        m = record["machine"]
        assert m["name"] == platform.node() and m["cores"] == os.cpu_count() and m["cpu"]
        assert isinstance(m["gpus"], list) and m["slurm_node"] is None
        assert record["package_versions"]["numpy"] == version("numpy")
        assert any(k.startswith("opencv") for k in record["package_versions"])  # cv2's distribution, by name


def test_the_reports_provenance_names_hosts_and_packages(campaign):
    from slamrun.analysis.provenance import provenance

    _, res = campaign
    p = provenance(res.results, pd.read_csv(res.results_csv))
    assert p.runs_host == f"{platform.node()} (2 runs)"
    assert f"numpy {version('numpy')}" in p.packages["reference_vo"]


def test_a_resume_with_nothing_to_run_keeps_the_span(campaign):
    from slamrun.engine.session import read_figures

    spec, res = campaign
    before = read_figures(res.results)
    assert before.elapsed_s and before.elapsed_s > 1
    again = run_campaign(load_spec(spec), log=lambda *a: None)
    assert again.results == res.results
    after = read_figures(res.results)
    assert after.elapsed_s == pytest.approx(before.elapsed_s) and not after.active


def test_each_run_records_the_code_that_ran_it_and_the_report_names_the_runs_commits(campaign):
    """run.json said `slamrun 0.1.0`; the report showed the commit of the code writing it, not of the runs (issue
    62). Each run records slamrun's commit (and whether its tree had changes); the report names the runs' commits
    and says when they came from more than one."""
    import subprocess

    from slamrun.analysis.provenance import provenance, run_commits

    _, res = campaign
    df = pd.read_csv(res.results_csv)
    from slamrun.backends.machine import source_commit

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    head = source_commit().split(" ")[0]  # this process's code (HEAD when it first looked; a commit since is not it)
    known = subprocess.run(["git", "-C", root, "cat-file", "-t", head], capture_output=True, text=True).stdout.strip()
    assert known == "commit" and df.slamrun_commit.str.startswith(head).all(), df.slamrun_commit.tolist()
    for run_dir in df.run_dir:
        assert json.loads((res.results / run_dir / "run.json").read_text())["slamrun_commit"].startswith(head)
    p = provenance(res.results, df)
    assert p.run_commits.startswith(f"{head}") and "2 run(s)" in p.run_commits
    two = df.assign(slamrun_commit=[f"{head}", "0123abc"])
    said = run_commits(two)
    assert said.startswith("made by 2 versions of the code") and "0123abc: 1 run(s)" in said


def test_the_stored_spec_is_read_back_through_the_spec_model():
    """The spec as run is read as RecordedSpec (typed as CampaignSpec types it): keys of another version and methods
    of a plug-in not installed here are no obstacle, a value of the wrong type or a spec that is no mapping gives
    nothing rather than a wrong figure."""
    from slamrun.engine.session import measurement_conditions
    from slamrun.engine.spec import RecordedSpec

    recorded = {
        "name": "study", "backend": "docker", "lanes": 2, "cpus_per_lane": 1, "contention_pct": 15,
        "methods": [{"name": "a_plugin_not_installed_here"}], "a_key_of_a_later_version": True,
    }  # fmt: skip
    spec = RecordedSpec.read(recorded)
    assert (spec.name, spec.backend, spec.lanes, spec.cpus_per_lane, spec.contention_pct) == (
        "study",
        "docker",
        2,
        1,
        15,
    )
    assert measurement_conditions(recorded) == "parallel: 2 lane(s) of 1 CPU(s) each side by side"
    assert [(m.run_label, m.params) for m in spec.methods] == [("a_plugin_not_installed_here", None)]
    both = RecordedSpec.read({"methods": [{"name": "dpvo", "label": "dpv_slam", "params": {"loop_closure": True}}]})
    assert both.methods[0].run_label == "dpv_slam" and both.methods[0].params == {"loop_closure": True}
    assert RecordedSpec.read({"lanes": "two"}) is None and RecordedSpec.read(["not", "a", "mapping"]) is None
    assert measurement_conditions({"lanes": "two"}) == "" and measurement_conditions(None) == ""
