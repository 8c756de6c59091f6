"""Every door to where slamrun writes goes through one guard; plug-ins never stop slamrun, never share a name unseen,
never write outside their run and fail as methods; a damaged ledger and a missing executable are one clear line.

Real processes throughout: `slamrun` as a subprocess, plug-ins as real packages (a module and its .dist-info with
entry points) in a folder on PYTHONPATH, real campaigns on the tiny synthetic sequences."""

from __future__ import annotations

import hashlib
import json
import os
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from tests.conftest import FAKE, fake_method, one_sequence

BIN = Path(sys.executable).parent


def slamrun(*args, env: dict | None = None, cwd: Path | None = None, timeout: float = 300):
    return subprocess.run(
        [str(BIN / "slamrun"), *map(str, args)],
        capture_output=True,
        text=True,
        env={**os.environ, **(env or {})},
        cwd=cwd,
        timeout=timeout,
    )


def digest(folder: Path) -> str:
    """Every name under `folder` (files, folders, links) and every file's bytes."""
    h = hashlib.sha256()
    for path in sorted(folder.rglob("*")):
        rel = path.relative_to(folder).as_posix()
        if path.is_symlink():
            h.update(f"L {rel} {os.readlink(path)}\n".encode())
        elif path.is_dir():
            h.update(f"D {rel}\n".encode())
        else:
            h.update(f"F {rel} {hashlib.sha256(path.read_bytes()).hexdigest()}\n".encode())
    return h.hexdigest()


def user_folder(path: Path) -> Path:
    """A folder of someone's own, with the very names slamrun writes (and a subfolder of their work)."""
    path.mkdir(parents=True)
    (path / "results.csv").write_text("method,score\nmine,1\n")
    (path / "spec.resolved.yaml").write_text("my: notes\n")
    (path / "report").mkdir()
    (path / "report" / "index.html").write_text("<p>my report</p>\n")
    (path / "thesis").mkdir()
    (path / "thesis" / "chapter1.tex").write_text("\\chapter{One}\n")
    return path


def spec_file(tmp_path: Path, dataset: Path, name: str = "t", **kw) -> Path:
    spec = {
        "name": name,
        "results": str(tmp_path / "results"),
        "cache": str(tmp_path / "cache"),
        "datasets": one_sequence(dataset),
        "methods": [fake_method()],
        "directions": ["forward"],
        "trials": 1,
        "timeout_s": 60,
        "retry_backoff_s": 0.01,
        "report": False,
    }
    spec.update(kw)
    for k in [k for k, v in spec.items() if v is None]:
        del spec[k]
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(spec))
    return path


def refused(out: subprocess.CompletedProcess, *words: str) -> None:
    assert out.returncode == 1, (out.returncode, out.stdout[-2000:], out.stderr[-2000:])
    assert "Traceback" not in out.stderr, out.stderr
    for w in words:
        assert w in out.stderr, (w, out.stderr)


# ---------------------------------------------------------------- item 1: one guard for every door


@pytest.mark.parametrize(
    "door",
    ["flag", "flag-dry-run", "plan-flag", "key", "default", "cache-key", "report", "verify-results", "images-verify"],
)
def test_a_users_folder_is_refused_at_every_door_before_anything_is_written(tmp_path, tiny_dataset, door, request):
    mine = user_folder(tmp_path / "mine")
    if door == "report":  # a results table of slamrun's kept among the user's own files, with their own report/
        (mine / "results.csv").write_bytes((request.getfixturevalue("finished_results") / "results.csv").read_bytes())
    before = digest(mine)
    work = tmp_path / "work"
    work.mkdir()
    if door in ("flag", "flag-dry-run", "plan-flag"):
        spec = spec_file(work, tiny_dataset)
        cmd = {
            "flag": ["campaign", spec, "--results", mine],
            "flag-dry-run": ["campaign", spec, "--dry-run", "--results", mine],
            "plan-flag": ["plan", spec, "--results", mine],
        }[door]
        out = slamrun(*cmd, cwd=work)
    elif door == "key":
        out = slamrun("campaign", spec_file(work, tiny_dataset, results=str(mine)), cwd=work)
    elif door == "default":  # no results key: results/<name> beside the working directory
        mine = tmp_path / "work" / "results" / "t"
        user_folder(mine)
        before = digest(mine)
        out = slamrun("campaign", spec_file(work, tiny_dataset, results=None), cwd=work)
    elif door == "cache-key":
        out = slamrun("campaign", spec_file(work, tiny_dataset, cache=str(mine)), cwd=work)
    elif door == "report":
        out = slamrun("report", mine, cwd=work)
    elif door == "verify-results":
        spec = spec_file(work, tiny_dataset)
        out = slamrun("verify", spec, "--results", mine, "--trials", "1", "--frames", "30", cwd=work)
    else:
        out = slamrun("images", "--verify", "--method", "dso", "--results", mine, cwd=work)
    refused(out, str(mine))
    assert "Traceback" not in out.stdout
    assert digest(mine) == before  # byte for byte
    if door not in ("report", "images-verify"):  # nothing else was written either: no results, no cache
        assert sorted(p.name for p in work.iterdir()) == sorted(["t.yaml"] + (["results"] if door == "default" else []))


@pytest.mark.parametrize("where", ["results", "above-results", "above-data"])
def test_the_view_cache_never_holds_the_results_or_a_dataset(tmp_path, tiny_dataset, where):
    """The cache deletes what in it is not a prepared view: it may neither be nor hold results or data."""
    cache = {"results": tmp_path / "results", "above-results": tmp_path, "above-data": tiny_dataset.parent}[where]
    spec = spec_file(tmp_path, tiny_dataset, cache=str(cache))
    before = digest(tiny_dataset)
    for args in (["validate", spec], ["campaign", spec]):
        refused(slamrun(*args), "cache:", "a folder of its own")
    assert not (tmp_path / "results").exists() and digest(tiny_dataset) == before


def test_the_guard_lets_slamrun_reuse_its_own_folders(tmp_path, tiny_dataset):
    """The folders slamrun made itself (results with --results, the cache, report/, verify's) are used again."""
    spec = spec_file(tmp_path, tiny_dataset)
    for _ in range(2):
        out = slamrun("campaign", spec, "--results", tmp_path / "flagged")
        assert out.returncode == 0, out.stderr
        assert slamrun("report", tmp_path / "flagged").returncode == 0
    empty = tmp_path / "empty"
    empty.mkdir()
    assert slamrun("campaign", spec, "--dry-run", "--results", empty).returncode == 0
    assert not any(empty.iterdir())  # a dry run writes nothing


def test_a_results_folder_belongs_to_one_campaign_name(tmp_path, tiny_dataset):
    first = spec_file(tmp_path, tiny_dataset, name="first")
    assert slamrun("campaign", first).returncode == 0
    results = tmp_path / "results"
    before = digest(results)
    second = spec_file(tmp_path, tiny_dataset, name="second")
    for args in (["campaign", second], ["campaign", second, "--dry-run"], ["validate", second]):
        out = slamrun(*args)
        refused(out, str(results), "'first'", "'second'")
        assert digest(results) == before
    other = spec_file(tmp_path, tiny_dataset, name="third", results=str(tmp_path / "elsewhere"))
    refused(slamrun("campaign", other, "--results", results), "'first'")
    assert digest(results) == before
    assert slamrun("campaign", first).returncode == 0  # its own name goes on


# ---------------------------------------------------------------- item 6: plug-ins


PLUGIN = """
import sys
from pathlib import Path

from slamrun.methods.base import Method

PY = {python!r}
FAKE = {fake!r}


class Good(Method):
    name = {name!r}
    native = True

    def command(self, view, workdir):
        return [PY, FAKE, "--times", str(view.path(view.times)), "--out", str(workdir / "trajectory.txt"),
                "--view", str(view.root)]
{extra}
"""


def plugin(site: Path, dist: str, version: str, module: str, name: str, extra: str = "", body: str | None = None):
    """A real installed package: `module`.py on the path and `dist`-`version`.dist-info with its entry point."""
    site.mkdir(exist_ok=True)
    source = body if body is not None else PLUGIN.format(python=sys.executable, fake=str(FAKE), name=name, extra=extra)
    (site / f"{module}.py").write_text(source)
    info = site / f"{dist.replace('-', '_')}-{version}.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {dist}\nVersion: {version}\n")
    (info / "entry_points.txt").write_text(f"[slamrun.methods]\n{name} = {module}:Good\n")
    return info


def with_site(site: Path) -> dict:
    return {"PYTHONPATH": os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep)}


def plugin_spec(tmp_path: Path, dataset: Path, name: str, **kw) -> Path:
    return spec_file(tmp_path, dataset, methods=[{"name": name}], retries=1, **kw)


def ledger_rows(results: Path) -> list[dict]:
    db = sqlite3.connect(f"file:{results / 'ledger.sqlite'}?mode=ro", uri=True)
    db.row_factory = sqlite3.Row
    try:
        return [dict(r) for r in db.execute("SELECT * FROM runs WHERE active = 1")]
    finally:
        db.close()


def test_a_plugin_that_exits_at_import_is_named_never_fatal(tmp_path, tiny_dataset):
    site = tmp_path / "site"
    plugin(site, "quitter", "0.1", "quitter_mod", "quitter", body="import sys\nsys.exit(3)\n")
    plugin(site, "fine", "1.0", "fine_mod", "fine")
    hollow = "from slamrun.methods.base import Method\n\nclass Good(Method):\n    name = 'hollow'\n"  # no command()
    plugin(site, "hollow", "1.0", "hollow_mod", "hollow", body=hollow)
    env = with_site(site)
    listed = slamrun("list-methods", env=env)
    assert listed.returncode == 0, listed.stderr
    assert "not registered: quitter" in listed.stdout and "SystemExit" in listed.stdout
    assert "not registered: hollow" in listed.stdout and "does not implement command" in listed.stdout
    assert "fine" in listed.stdout
    out = slamrun("validate", plugin_spec(tmp_path, tiny_dataset, "fine"), env=env)
    assert out.returncode == 0, out.stderr
    bad = slamrun("validate", plugin_spec(tmp_path, tiny_dataset, "quitter"), env=env)
    refused(bad, "methods[0].name", "quitter_mod:Good", "SystemExit")
    refused(slamrun("validate", plugin_spec(tmp_path, tiny_dataset, "hollow"), env=env), "does not implement command")


def test_two_packages_registering_one_name_are_refused_naming_both(tmp_path, tiny_dataset):
    site = tmp_path / "site"
    plugin(site, "alpha-vo", "1.0", "alpha_mod", "twin")
    plugin(site, "beta-vo", "2.3", "beta_mod", "twin")
    env = with_site(site)
    listed = slamrun("list-methods", env=env)
    assert listed.returncode == 0
    line = next(line for line in listed.stdout.splitlines() if "twin" in line)
    assert "not registered: twin" in line
    text = listed.stdout.replace("\n", " ")
    assert "alpha-vo 1.0" in text and "beta-vo 2.3" in text and "built-in" not in text
    spec = plugin_spec(tmp_path, tiny_dataset, "twin")
    for args in (["validate", spec], ["campaign", spec], ["campaign", spec, "--dry-run"]):
        refused(slamrun(*args, env=env), "methods[0].name", "alpha-vo", "beta-vo")
    assert not (tmp_path / "results").exists()


def test_the_providing_package_is_recorded_and_keys_the_runs(tmp_path, tiny_dataset):
    site = tmp_path / "site"
    info = plugin(site, "my-vo", "1.0", "my_mod", "myvo")
    env = with_site(site)
    spec = plugin_spec(tmp_path, tiny_dataset, "myvo")
    out = slamrun("campaign", spec, env=env)
    assert out.returncode == 0, out.stdout + out.stderr
    (row,) = ledger_rows(tmp_path / "results")
    assert row["status"] == "done"
    record = json.loads((Path(row["run_dir"]) / "run.json").read_text())
    assert record["provider"] == {"distribution": "my-vo", "version": "1.0"}
    listed = slamrun("list-methods", env=env).stdout
    assert "my-vo 1.0" in listed
    # the same name from another release is another implementation: new runs, never pooled with the old ones
    info.rename(site / "my_vo-2.0.dist-info")
    (site / "my_vo-2.0.dist-info" / "METADATA").write_text("Metadata-Version: 2.1\nName: my-vo\nVersion: 2.0\n")
    out = slamrun("campaign", spec, env=env)
    assert out.returncode == 0, out.stdout + out.stderr
    (row2,) = ledger_rows(tmp_path / "results")
    assert row2["settings"] != row["settings"] and row2["status"] == "done"
    assert json.loads((Path(row2["run_dir"]) / "run.json").read_text())["provider"]["version"] == "2.0"


OUTSIDE = """
    def configure(self, view, workdir):
        return {{"settings.yaml": "ok\\n", {target!r}: "written by a plug-in\\n"}}
"""

RAISES = {
    "command-raises": """
    def command(self, view, workdir):
        raise ValueError("no calibration for this camera")
""",
    "command-exits": """
    def command(self, view, workdir):
        sys.exit("giving up")
""",
    "configure-raises": """
    def configure(self, view, workdir):
        return {}["settings"]
""",
    "read-raises": """
    def read_trajectory(self, workdir, view):
        raise RuntimeError("parser bug")
""",
    "read-returns-garbage": """
    def read_trajectory(self, workdir, view):
        return [[0.0, 1.0, 2.0]]
""",
    "read-returns-a-broken-trajectory": """
    def read_trajectory(self, workdir, view):
        from slamrun.core.trajectory import Trajectory
        import numpy as np
        return Trajectory(np.arange(3.0), np.zeros((2, 3)), np.zeros((5, 4)))
""",
}


@pytest.mark.parametrize("target", ["absolute", "dotdot"])
def test_config_paths_outside_the_run_are_refused_as_the_methods_fault(tmp_path, tiny_dataset, target):
    outside = tmp_path / "outside.txt"
    rel = str(outside) if target == "absolute" else "../../../../../../../outside.txt"
    site = tmp_path / "site"
    plugin(site, "leaky", "0.3", "leaky_mod", "leaky", extra=OUTSIDE.format(target=rel))
    env = with_site(site)
    out = slamrun("campaign", plugin_spec(tmp_path, tiny_dataset, "leaky"), env=env)
    assert out.returncode == 0, out.stdout + out.stderr  # a failed run is a result of the method
    assert not outside.exists()
    assert not list(tmp_path.rglob("outside.txt"))
    (row,) = ledger_rows(tmp_path / "results")
    assert (row["status"], row["failure"], row["attempts"]) == ("failed", "crashed", 1), row
    assert "leaky" in row["message"] and "outside" in row["message"] and "\n" not in row["message"]
    assert not list((tmp_path / "results" / "runs").rglob("settings.yaml"))  # nothing written of it at all


@pytest.mark.parametrize("case", sorted(RAISES))
def test_a_plugin_that_raises_is_the_methods_failure_not_infra(tmp_path, tiny_dataset, case):
    site = tmp_path / "site"
    plugin(site, "shaky-vo", "0.2", "shaky_mod", "shaky", extra=RAISES[case])
    env = with_site(site)
    spec = plugin_spec(tmp_path, tiny_dataset, "shaky")
    out = slamrun("campaign", spec, env=env)
    assert out.returncode == 0, out.stdout + out.stderr
    (row,) = ledger_rows(tmp_path / "results")
    assert (row["status"], row["failure"], row["attempts"]) == ("failed", "crashed", 1), row
    message = row["message"]
    assert "Traceback" not in message and "\n" not in message
    assert "shaky" in message and "shaky-vo 0.2" in message
    exc = {
        "command-raises": "ValueError",
        "command-exits": "SystemExit",
        "configure-raises": "KeyError",
        "read-returns-garbage": "returned list, not a Trajectory",
        "read-returns-a-broken-trajectory": "returned a Trajectory of 3 times, 2 positions and 5 rotations",
    }
    assert exc.get(case, "RuntimeError") in message, message
    record = json.loads((Path(row["run_dir"]) / "run.json").read_text())
    assert record["failure"] == "crashed" and record["provider"]["distribution"] == "shaky-vo"
    out = slamrun("campaign", spec, env=env)  # a method's failure is a result: never retried
    (again,) = ledger_rows(tmp_path / "results")
    assert (again["status"], again["attempts"], again["message"]) == ("failed", 1, message)


# ---------------------------------------------------------------- item 7: damaged ledger, missing executable


@pytest.fixture(scope="module")
def finished_results(tmp_path_factory, tiny_dataset) -> Path:
    root = tmp_path_factory.mktemp("finished")
    spec = spec_file(root, tiny_dataset, directions=["forward", "backward"], trials=3)
    out = slamrun("campaign", spec)
    assert out.returncode == 0, out.stderr
    return root / "results"


@pytest.mark.parametrize("damage", ["garbage", "truncated"])
@pytest.mark.parametrize("command", [["status", "--json"], ["status"], ["report"], ["stats"]])
def test_a_damaged_ledger_is_one_clear_error_for_every_reader(tmp_path, finished_results, damage, command):
    results = tmp_path / "results"
    subprocess.run(["cp", "-a", str(finished_results), str(results)], check=True)
    ledger = results / "ledger.sqlite"
    data = ledger.read_bytes()
    if damage == "garbage":
        ledger.write_bytes(os.urandom(len(data)))
    else:
        assert len(data) >= 4 * 4096
        ledger.write_bytes(data[: len(data) // 2])
    out = slamrun(*command[:1], results, *command[1:])
    refused(out, str(ledger))
    assert len(out.stderr.strip().splitlines()) == 1, out.stderr
    assert "move it aside" in out.stderr


@pytest.mark.parametrize("method", ["orb_slam2", "external", "relative"])
def test_an_executable_that_does_not_exist_is_refused_by_validate(tmp_path, tiny_dataset, method):
    missing = tmp_path / "build" / "mono_tum"
    m = {
        "orb_slam2": {"name": "orb_slam2", "params": {"executable": str(missing)}},
        "external": {"name": "external", "params": {"argv": [str(missing), "{times}", "{out}"]}},
        "relative": {"name": "dso", "params": {"executable": "build/dso_dataset"}},
    }[method]
    spec = spec_file(tmp_path, tiny_dataset, methods=[m], backend="local")
    for args in (["validate", spec], ["campaign", spec]):
        out = slamrun(*args)
        refused(out, "methods[0]")
        assert (str(missing) if method != "relative" else "build/dso_dataset") in out.stderr
    assert not (tmp_path / "results").exists()
    # a program that exists is accepted, on PATH or by its path
    exe = tmp_path / "bin" / "mono_tum"
    exe.parent.mkdir()
    exe.write_text("#!/bin/sh\nexit 0\n")
    exe.chmod(0o755)
    ok = {"name": "orb_slam2", "params": {"executable": str(exe)}}
    assert slamrun("validate", spec_file(tmp_path, tiny_dataset, methods=[ok], backend="local")).returncode == 0
    on_path = {"name": "external", "params": {"argv": ["sh", "-c", "exit 0"]}}
    assert slamrun("validate", spec_file(tmp_path, tiny_dataset, methods=[on_path])).returncode == 0
    exe.chmod(0o644)  # there, but not executable
    refused(slamrun("validate", spec_file(tmp_path, tiny_dataset, methods=[ok], backend="local")), "not executable")
