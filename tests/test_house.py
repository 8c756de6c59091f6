"""A method is one folder: a copy of a CPU method's folder under a new name is a new built-in method, listed, buildable
and verified, with no other file touched (slamrun/methods/<name>/: its adapter, its image/ recipe, its declaration)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def slamrun(tree: Path, *args, cwd: Path) -> subprocess.CompletedProcess:
    """slamrun from the copied tree (first on the path: the installed one is an editable finder, consulted last)."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    return subprocess.run(
        [sys.executable, "-m", "slamrun.cli", *map(str, args)], capture_output=True, text=True, env=env, cwd=cwd
    )


def test_a_copied_method_folder_is_listed_buildable_and_verified(tmp_path):
    tree = tmp_path / "tree"
    shutil.copytree(ROOT / "slamrun", tree / "slamrun", ignore=shutil.ignore_patterns("__pycache__"))
    methods = tree / "slamrun" / "methods"
    shutil.copytree(methods / "reference_vo", methods / "my_vo")  # the one change: a folder
    check = subprocess.run(
        [sys.executable, "-c", "import slamrun; print(slamrun.__file__)"],
        capture_output=True, text=True, env={**os.environ, "PYTHONPATH": str(tree)}, cwd=tmp_path,
    )  # fmt: skip
    assert check.stdout.strip() == str(tree / "slamrun" / "__init__.py")

    listed = slamrun(tree, "list-methods", "--json", cwd=tmp_path)
    assert listed.returncode == 0, listed.stderr
    mine = json.loads(listed.stdout)["my_vo"]
    assert mine["image"] == "slamrun/my_vo:latest" and mine["native"] and mine["gpu"] == "no"

    images = slamrun(tree, "images", "--list", cwd=tmp_path)
    assert images.returncode == 0, images.stderr
    assert "my_vo: slamrun/my_vo:latest <- my_vo/image/Dockerfile" in images.stdout
    assert "reference_vo: slamrun/reference_vo:latest <- reference_vo/image/Dockerfile" in images.stdout

    data = tmp_path / "data"
    assert slamrun(tree, "synth", "--frames", "20", data / "s", cwd=tmp_path).returncode == 0
    spec = tmp_path / "house.yaml"
    spec.write_text(
        f"name: house\nbackend: local\nmethods:\n  - name: my_vo\n"
        f"datasets:\n  - name: d\n    path: {data}\n    sequences: [s]\n"
    )
    results = tmp_path / "verify"
    out = slamrun(tree, "verify", spec, "--trials", "1", "--frames", "60", "--results", results, cwd=tmp_path)
    assert out.returncode == 0, out.stdout + out.stderr
    (row,) = json.loads((results / "verify.json").read_text())
    assert row["method"] == "my_vo" and row["runs_ok"] == row["runs"] == 4 and row["bound"] == 0.05, row
    assert row["passed"] and row["backend"] == "local", row
