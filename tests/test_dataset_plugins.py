"""A lab's own dataset layout from its own package: `slamrun new-dataset` writes it, pip installs it (into a folder
on PYTHONPATH, its dist-info with the entry point), its entry point registers it, `slamrun list-datasets` names it
with its package, `slamrun synth` writes it and a campaign runs on it; a plug-in that cannot load, one that takes a
built-in's name and a name two packages register are named, never fatal."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]


def run(*args, env: dict | None = None, check: bool = True, cwd: Path = ROOT) -> subprocess.CompletedProcess:
    out = subprocess.run(
        [str(a) for a in args], capture_output=True, text=True, cwd=cwd, timeout=900, env={**os.environ, **(env or {})}
    )
    if check and out.returncode:
        raise AssertionError(f"{args} exited {out.returncode}:\n{out.stdout[-3000:]}\n{out.stderr[-3000:]}")
    return out


def slamrun(*args, env: dict | None = None, check: bool = True) -> subprocess.CompletedProcess:
    return run(sys.executable, "-m", "slamrun.cli", *args, env=env, check=check)


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> dict:
    """The package `slamrun new-dataset mylab` writes, as written, pip-installed into a folder put on PYTHONPATH;
    with it, entry points a broken package would have (one that cannot load, one taking a built-in's name) and a
    second package registering one of its names."""
    tmp = tmp_path_factory.mktemp("plugin")
    pkg = tmp / "slamrun-dataset-mylab"
    slamrun("new-dataset", "mylab", "--dest", pkg)
    layout = pkg / "slamrun_dataset_mylab" / "layout.py"
    assert layout.read_text().count("FILL IN") >= 4  # the lines a person changes are marked
    pyproject = pkg / "pyproject.toml"
    extra = (
        'broken = "slamrun_dataset_mylab.layout:NOPE"\n'
        'euroc = "slamrun_dataset_mylab.layout:LAYOUT"\n'
        'twice = "slamrun_dataset_mylab.layout:LAYOUT"\n'
        'number = "slamrun_dataset_mylab.layout:MAX_GAP_S"\n'
        'renamed = "slamrun_dataset_mylab.layout:LAYOUT"\n'
    )
    pyproject.write_text(pyproject.read_text().replace(':LAYOUT"\n', ':LAYOUT"\n' + extra, 1))
    site = tmp / "site"
    run(sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--no-build-isolation", "--target", site, pkg)
    other = site / "other_lab-1.0.dist-info"  # a second installed package registering `twice` too
    other.mkdir()
    (other / "METADATA").write_text("Metadata-Version: 2.1\nName: other-lab\nVersion: 1.0\n")
    (other / "entry_points.txt").write_text("[slamrun.datasets]\ntwice = other_lab:LAYOUT\n")
    return {"pkg": pkg, "env": {"PYTHONPATH": str(site)}, "tmp": tmp}


def test_the_plugin_is_listed_with_its_package_and_the_broken_ones_are_named(installed):
    out = slamrun("list-datasets", env=installed["env"]).stdout
    row = next(line for line in out.splitlines() if "│ mylab" in line)
    assert "slamrun-dataset-mylab 0.1.0" in row
    listed = " ".join(out.split())  # rich wraps long lines
    assert "│ icl-nuim" in listed and "built-in" in listed
    assert "not registered: broken: plug-in slamrun_dataset_mylab.layout:NOPE" in listed
    assert "cannot be imported: AttributeError" in listed
    assert "not registered: euroc: plug-in" in listed and "is a built-in layout" in listed
    assert "not registered: twice: 'twice' is registered by 2 installed plug-ins" in listed
    assert "not registered: number: plug-in slamrun_dataset_mylab.layout:MAX_GAP_S" in listed
    assert "is float, not a slamrun.datasets.Layout" in listed
    assert "not registered: renamed:" in listed and "its layout's name is 'mylab', not 'renamed'" in listed
    # without the package, nothing of it
    assert "mylab" not in slamrun("list-datasets").stdout


def test_the_plugin_layout_synthesised_read_and_run_in_a_campaign(installed, tmp_path):
    env = installed["env"]
    out = slamrun(
        "synth", tmp_path / "data" / "lab1", "--layout", "mylab", "--frames", 60, "--size", "320x240", env=env
    )
    assert "60 frames, mylab layout" in out.stdout
    assert (tmp_path / "data" / "lab1" / "frames.csv").is_file()
    spec = {
        "name": "lab",
        "results": str(tmp_path / "results"),
        "cache": str(tmp_path / "cache"),
        "datasets": [
            {"name": "lab", "layout": "mylab", "path": str(tmp_path / "data"), "sequences": ["lab1"]},
            {  # and one the campaign generates with the plug-in's writer
                "name": "lab-synth",
                "layout": "mylab",
                "path": str(tmp_path / "gen"),
                "sequences": ["lab2"],
                "synthetic": {"frames": 60, "seed": 4, "size": "320x240"},
            },
        ],
        "methods": [{"name": "reference_vo"}],
        "trials": 1,
        "lanes": 2,
        "timeout_s": 300,
        "report": False,
    }
    (tmp_path / "spec.yaml").write_text(yaml.safe_dump(spec))
    out = slamrun("campaign", tmp_path / "spec.yaml", env=env)
    df = pd.read_csv(tmp_path / "results" / "results.csv")
    assert len(df) == 4 and df.status.eq("done").all(), (out.stdout, df.message.tolist())
    assert df.eval_status.eq("ok").all() and df.ate_rmse.notna().all() and df.rpe_t_rmse.notna().all()
    assert (df.ate_rmse < 0.01 * 2 * 2.3 * 3.1416).all(), df[["dataset", "direction", "ate_rmse"]]

    # the package's own tests pass as written
    run(sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", installed["pkg"] / "tests", env=env)

    # a spec naming the broken plug-in: one line naming it; one naming the package's layout without it installed
    spec["datasets"] = [{"name": "b", "layout": "broken", "path": str(tmp_path / "data"), "sequences": ["lab1"]}]
    (tmp_path / "spec.yaml").write_text(yaml.safe_dump(spec))
    bad = slamrun("validate", tmp_path / "spec.yaml", env=env, check=False)
    assert bad.returncode == 1 and "layout 'broken': plug-in slamrun_dataset_mylab.layout:NOPE" in bad.stderr
    spec["datasets"][0]["layout"] = "mylab"
    (tmp_path / "spec.yaml").write_text(yaml.safe_dump(spec))
    bad = slamrun("validate", tmp_path / "spec.yaml", check=False)
    assert bad.returncode == 1 and "unknown layout 'mylab'" in bad.stderr and "Traceback" not in bad.stderr


def test_a_plugins_reader_that_raises_is_a_dataset_error_naming_it(installed, tmp_path):
    """Whatever a plug-in's function raises is its failure, named with the plug-in, never a traceback."""
    env = installed["env"]
    folder = tmp_path / "lab3"
    slamrun("synth", folder, "--layout", "mylab", "--frames", 30, "--size", "160x120", env=env)
    (folder / "poses.csv").write_text("not,a,pose\n")
    out = slamrun("evaluate", "--gt", folder, folder / "frames.csv", env=env, check=False)
    assert out.returncode == 1 and "poses.csv:1: not numbers" in out.stderr and "Traceback" not in out.stderr
    (folder / "intrinsics.txt").write_text("100 100 80 60 1e999 120\n")  # int(inf): OverflowError in its reader
    out = slamrun("evaluate", "--gt", folder, folder / "frames.csv", env=env, check=False)
    assert out.returncode == 1 and "Traceback" not in out.stderr, out.stderr
    who = "plug-in layout mylab (slamrun-dataset-mylab 0.1.0)"
    assert f"{who}: reading the sequence on {folder} failed: OverflowError" in out.stderr


def test_new_dataset_never_writes_over_a_folder_or_takes_a_built_in_name(tmp_path):
    (tmp_path / "taken").mkdir()
    (tmp_path / "taken" / "notes.txt").write_text("mine\n")
    out = slamrun("new-dataset", "mine", "--dest", tmp_path / "taken", check=False)
    assert out.returncode == 1 and "not empty" in out.stderr
    out = slamrun("new-dataset", "tartanair", "--dest", tmp_path / "d", check=False)
    assert out.returncode == 1 and "already" in out.stderr and not (tmp_path / "d").exists()
    out = slamrun("new-dataset", "My_Lab", "--dest", tmp_path / "e", check=False)
    assert out.returncode == 1 and "lower-case" in out.stderr and not (tmp_path / "e").exists()


def test_a_plugins_unsorted_times_are_refused_by_validate_before_any_run(installed, tmp_path):
    """The plug-in as installed, its reader changed to give its frames' times reversed (a lab's reader with a
    bug): `slamrun validate` and `slamrun campaign` stop with one line naming the plug-in, its package and the
    folder; no run starts (they were charged `bad_timestamps` to the method)."""
    import shutil

    site = tmp_path / "site"
    shutil.copytree(Path(installed["env"]["PYTHONPATH"]), site)
    layout_py = site / "slamrun_dataset_mylab" / "layout.py"
    layout_py.write_text(
        layout_py.read_text()
        + "\n\nimport dataclasses as _dc\n_read = read\n\n\ndef _reversed(root):\n"
        + "    seq = _read(root)\n    return _dc.replace(seq, timestamps=seq.timestamps[::-1].copy())\n\n\n"
        + "LAYOUT = _dc.replace(LAYOUT, read=_reversed)\n"
    )
    env = {"PYTHONPATH": str(site)}
    slamrun("synth", tmp_path / "data" / "lab1", "--layout", "mylab", "--frames", 20, "--size", "160x120", env=env)
    spec = {
        "name": "lab",
        "results": str(tmp_path / "results"),
        "cache": str(tmp_path / "cache"),
        "datasets": [{"name": "lab", "layout": "mylab", "path": str(tmp_path / "data"), "sequences": ["lab1"]}],
        "methods": [{"name": "reference_vo"}],
        "trials": 1,
        "report": False,
    }
    (tmp_path / "spec.yaml").write_text(yaml.safe_dump(spec))
    who = "plug-in layout mylab (slamrun-dataset-mylab 0.1.0)"
    for command in ("validate", "campaign"):
        out = slamrun(command, tmp_path / "spec.yaml", env=env, check=False)
        assert out.returncode != 0 and "Traceback" not in out.stderr, out.stderr
        text = " ".join(out.stderr.split())
        assert f"{who}: the sequence it read from {tmp_path / 'data' / 'lab1'} cannot be run" in text, text
        assert "frame times must increase: frame 1" in text
    assert not (tmp_path / "results" / "runs").exists() or not any((tmp_path / "results" / "runs").iterdir())
