"""A method from the user's own package: `slamrun new-method` writes it, pip installs it into this venv, its entry
point registers it, a campaign runs it and `slamrun verify` verifies it; a broken plug-in is named, never fatal."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

BIN = Path(sys.executable).parent


def run(*args: str, cwd: Path | None = None, check: bool = True) -> subprocess.CompletedProcess:
    out = subprocess.run(args, capture_output=True, text=True, cwd=cwd, timeout=900)
    if check and out.returncode:
        raise AssertionError(f"{args} exited {out.returncode}:\n{out.stdout[-3000:]}\n{out.stderr[-3000:]}")
    return out


@pytest.fixture
def installed(tmp_path):
    """The package `slamrun new-method mymethod` writes, with its lines filled in as a user would: the program is
    a wrapper around this project's reference VO (standing for the user's own build), installed into this venv."""
    pkg = tmp_path / "slamrun-mymethod"
    run(str(BIN / "slamrun"), "new-method", "mymethod", "--dest", str(pkg))
    adapter = pkg / "slamrun_mymethod" / "adapter.py"
    text = adapter.read_text()
    assert text.count("FILL IN") >= 4  # the lines a person fills in are marked
    text = text.replace("    lost_pattern = None", '    lost_pattern = r"^LOST"')
    adapter.write_text(
        text.replace("    not_initialized_pattern = None", '    not_initialized_pattern = r"^NOT INITIALIZED"')
    )
    wrapper = pkg / "bin" / "mymethod"
    wrapper.parent.mkdir()
    vo = f"{sys.executable} -m slamrun.methods.reference_vo"
    wrapper.write_text(f'#!/bin/sh\nexec {vo} --images "$1" --times "$2" --camera "$3" --out "$4"\n')
    wrapper.chmod(0o755)
    pyproject = pkg / "pyproject.toml"  # and an entry point that cannot load, as a broken package would have
    pyproject.write_text(
        pyproject.read_text().replace(':Mymethod"\n', ':Mymethod"\nbroken = "slamrun_mymethod.adapter:Nope"\n')
    )
    pip = [sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--no-build-isolation", str(pkg)]
    run(*pip)
    try:
        yield pkg, wrapper
    finally:
        run(sys.executable, "-m", "pip", "uninstall", "-y", "-q", "slamrun-mymethod", check=False)


def test_a_plugin_method_registers_runs_and_verifies(installed, tmp_path):
    from slamrun.datasets.make_synthetic import generate

    pkg, wrapper = installed
    generate(tmp_path / "data" / "room", frames=90, seed=2)
    listed = run(str(BIN / "slamrun"), "list-methods").stdout
    assert "mymethod" in listed and "slamrun-mymethod" in listed
    assert "not registered: broken" in listed and "cannot be imported" in listed  # named, the others unharmed

    spec = {
        "name": "plugin",
        "results": str(tmp_path / "results"),
        "cache": str(tmp_path / "cache"),
        "datasets": [{"name": "synth", "path": str(tmp_path / "data"), "sequences": ["room"]}],
        "methods": [{"name": "mymethod", "params": {"executable": str(wrapper)}}],
        "trials": 1,
        "lanes": 2,
        "timeout_s": 120,
        "report": False,
    }
    (tmp_path / "spec.yaml").write_text(yaml.safe_dump(spec))
    out = run(str(BIN / "slamrun"), "campaign", str(tmp_path / "spec.yaml"))
    assert "done 2" in out.stdout, out.stdout

    verified = run(
        str(BIN / "slamrun"), "verify", str(tmp_path / "spec.yaml"), "--results", str(tmp_path / "verify"),
        "--trials", "1", "--frames", "90",
    )  # fmt: skip
    table = (tmp_path / "verify" / "verify.md").read_text()
    row = next(line for line in table.splitlines() if line.startswith("| mymethod |"))
    assert "| 4/4 |" in row and row.endswith("| yes |"), verified.stdout

    # the package's own tests pass as written
    env = {**os.environ, "PYTHONPATH": str(pkg)}
    subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(pkg / "tests")], check=True, env=env
    )

    spec["methods"] = [{"name": "broken"}]
    (tmp_path / "spec.yaml").write_text(yaml.safe_dump(spec))
    bad = run(str(BIN / "slamrun"), "validate", str(tmp_path / "spec.yaml"), check=False)
    assert bad.returncode == 1 and "methods[0].name: plug-in slamrun_mymethod.adapter:Nope" in bad.stderr


def test_new_method_never_writes_over_a_folder(tmp_path):
    (tmp_path / "taken").mkdir()
    (tmp_path / "taken" / "notes.txt").write_text("mine\n")
    out = run(str(BIN / "slamrun"), "new-method", "mine", "--dest", str(tmp_path / "taken"), check=False)
    assert out.returncode == 1 and "not empty" in out.stderr
    out = run(str(BIN / "slamrun"), "new-method", "dso", "--dest", str(tmp_path / "d"), check=False)
    assert out.returncode == 1 and "already" in out.stderr and not (tmp_path / "d").exists()


@pytest.mark.parametrize(
    "args, said",
    [
        (["new-method", "a" * 300], "a method name of 300 characters; at most 64"),
        (["new-method", "profile"], "would name the adapter's class Profile"),
        (["new-method", "direction"], "would name the adapter's class Direction"),
        (["new-method", "prepared_view"], "would name the adapter's class PreparedView"),
        (["new-method", "foo", "--dest", "dangling"], "dangling is a symbolic link"),
        (["new-method", "foo", "--dest", "afile/sub"], "afile is a file, not a folder"),
        (["new-dataset", "my-lab", "--dest", "afile/sub"], "afile is a file, not a folder"),
        (["new-dataset", "a" * 300], "a layout name of 300 characters"),
    ],
)
def test_new_package_doors_say_one_line_not_a_traceback(tmp_path, args, said):
    """A 300-character name, a dangling --dest link, a --dest under a file were tracebacks; profile, direction and
    prepared_view wrote packages whose own tests failed (the class shadowed an imported name)."""
    import subprocess
    import sys

    (tmp_path / "dangling").symlink_to(tmp_path / "nowhere" / "x")
    (tmp_path / "afile").write_text("mine\n")
    out = subprocess.run([sys.executable, "-m", "slamrun.cli", *args], capture_output=True, text=True, cwd=tmp_path)
    assert out.returncode != 0 and "Traceback" not in out.stderr, out.stderr
    assert said in out.stderr and len(out.stderr.strip().splitlines()) == 1, out.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile", "dangling"]  # nothing written
    assert (tmp_path / "afile").read_text() == "mine\n"
