"""Every plug-in attribute and call slamrun reads goes through the plug-in guard (issue 63, items 6 and 7): a bad
`threads` or a failing `busy_threads()` is the plug-in's one-line error before any run, and a run it finished stays
done; a method folder without a Method class is named and the other methods work; a plug-in import that hangs is
given up after its limit.

Real processes throughout: `slamrun` as a subprocess, plug-ins as real packages (a module and its .dist-info with an
entry point) in a folder on PYTHONPATH, real campaigns on the tiny synthetic sequences."""

from __future__ import annotations

import json
import os
import shutil
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from tests.conftest import FAKE, fake_method, one_sequence

BIN = Path(sys.executable).parent
ROOT = Path(__file__).resolve().parents[1]

PLUGIN = """
import os
import sys

from slamrun.methods import Method

PY = {python!r}
FAKE = {fake!r}
STARTED = {started!r}


class Good(Method):
    name = {name!r}
    native = True

    def command(self, view, workdir):
        return ["sh", "-c", 'touch "$0" && exec "$@"', STARTED, PY, FAKE, "--times", str(view.path(view.times)),
                "--out", str(workdir / "trajectory.txt"), "--view", str(view.root)]
{extra}
"""


def plugin(site: Path, dist: str, module: str, name: str, extra: str = "", body: str | None = None) -> None:
    """A real installed package: `module`.py on the path and `dist`-0.1.dist-info with its entry point `name`."""
    site.mkdir(exist_ok=True)
    started = str(site / f"{name}.started")  # the run's process touches it as it starts
    source = PLUGIN.format(python=sys.executable, fake=str(FAKE), started=started, name=name, extra=extra)
    (site / f"{module}.py").write_text(body if body is not None else source)
    info = site / f"{dist.replace('-', '_')}-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {dist}\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(f"[slamrun.methods]\n{name} = {module}:Good\n")


def slamrun(*args, env: dict | None = None, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run(
        [str(BIN / "slamrun"), *map(str, args)],
        capture_output=True,
        text=True,
        env={**os.environ, **(env or {})},
        timeout=timeout,
    )


def with_site(site: Path, **more: str) -> dict:
    return {"PYTHONPATH": os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep), **more}


def spec_file(tmp_path: Path, dataset: Path, methods: list[dict], **kw) -> Path:
    spec = {
        "name": "t",
        "results": str(tmp_path / "results"),
        "cache": str(tmp_path / "cache"),
        "datasets": one_sequence(dataset),
        "methods": methods,
        "directions": ["forward"],
        "trials": 1,
        "timeout_s": 60,
        "retries": 1,
        "retry_backoff_s": 0.01,
        "report": False,
        **kw,
    }
    path = tmp_path / "spec.yaml"
    path.write_text(yaml.safe_dump(spec))
    return path


def refused(out: subprocess.CompletedProcess, *words: str) -> None:
    assert out.returncode == 1, (out.returncode, out.stdout[-2000:], out.stderr[-2000:])
    assert "Traceback" not in out.stderr + out.stdout, out.stderr
    for w in words:
        assert w in out.stderr, (w, out.stderr)


def ledger_rows(results: Path) -> list[dict]:
    db = sqlite3.connect(f"file:{results / 'ledger.sqlite'}?mode=ro", uri=True)
    db.row_factory = sqlite3.Row
    try:
        return [dict(r) for r in db.execute("SELECT * FROM runs WHERE active = 1")]
    finally:
        db.close()


# ---------------------------------------------------------------- item 6: threads and busy_threads


EXPECTED = "expected an int >= 1, or None"

BAD_THREADS = {
    "threads-text": ("    threads = '2'\n", "threads = '2'"),
    "threads-negative": ("    threads = -1\n", "threads = -1"),
    "threads-fraction": ("    threads = 2.5\n", "threads = 2.5"),
    "threads-bool": ("    threads = True\n", "threads = True"),
    "busy-raises": (
        "    def busy_threads(self):\n        raise ValueError('no thread count')\n",
        "Good.busy_threads() raised ValueError: no thread count",
    ),
    "busy-returns-text": ("    def busy_threads(self):\n        return '3'\n", "Good.busy_threads() returned '3'"),
    "busy-returns-zero": ("    def busy_threads(self):\n        return 0\n", "Good.busy_threads() returned 0"),
}


@pytest.mark.parametrize("case", sorted(BAD_THREADS))
def test_a_bad_thread_count_is_the_plugins_one_line_error_before_any_run(tmp_path, tiny_dataset, case):
    """`threads = "2"` or a raising busy_threads() passed validate and turned a run that finished with a good
    trajectory into `infra` with a traceback (own_wait_pct); now refused before any run, naming the plug-in."""
    extra, says = BAD_THREADS[case]
    site = tmp_path / "site"
    plugin(site, "count-vo", "count_mod", "countvo", extra=extra)
    env = with_site(site)
    spec = spec_file(tmp_path, tiny_dataset, [{"name": "countvo"}])
    for args in (["validate", spec], ["campaign", spec]):
        out = slamrun(*args, env=env)
        refused(out, "methods[0]", "countvo", "count-vo 0.1", says)
        line = next(line for line in out.stderr.splitlines() if says in line)
        assert case == "busy-raises" or EXPECTED in line, line
    assert not (tmp_path / "results").exists()
    assert not (site / "countvo.started").exists()  # no run started
    if case.startswith("threads"):  # a class's own declaration: not registered at all, listed with why
        listed = slamrun("list-methods", env=env)
        assert listed.returncode == 0, listed.stderr
        assert "not registered: countvo" in listed.stdout and says in listed.stdout.replace("\n", " ")


AFTER_THE_RUN = {
    "raises": "            raise RuntimeError('lost my count')\n",
    "returns-text": "            return 'many'\n",
}


@pytest.mark.parametrize("case", sorted(AFTER_THE_RUN))
def test_a_busy_threads_failing_after_the_run_leaves_the_run_done(tmp_path, tiny_dataset, case):
    """busy_threads() answers before the run and fails once the run's process has started (at own_wait_pct, after
    the run): the run, finished with a good trajectory, stays done; its own-wait allowance is 0, said in its message."""
    site = tmp_path / "site"
    extra = (
        "    def busy_threads(self):\n"
        "        if os.path.exists(STARTED):\n" + AFTER_THE_RUN[case] + "        return 1\n"
    )
    plugin(site, "late-vo", "late_mod", "latevo", extra=extra)
    env = with_site(site)
    spec = spec_file(tmp_path, tiny_dataset, [{"name": "latevo"}])
    out = slamrun("campaign", spec, env=env)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    assert "Traceback" not in out.stdout + out.stderr, out.stdout + out.stderr
    assert (site / "latevo.started").exists()
    (row,) = ledger_rows(tmp_path / "results")
    assert (row["status"], row["attempts"]) == ("done", 1), row
    record = json.loads((Path(row["run_dir"]) / "run.json").read_text())
    assert record["status"] == "done" and record["cpu_wait_own_pct"] == 0
    message = record["message"]
    assert "plug-in latevo (late-vo 0.1)" in message and "busy_threads()" in message, message
    assert "own-wait allowance taken as its measured excess alone" in message and "\n" not in message, message
    assert row["message"] == message


def test_busy_threads_is_a_guarded_call():
    from slamrun.methods.base import GUARDED_CALLS

    assert "busy_threads" in GUARDED_CALLS


# ---------------------------------------------------------------- item 7: a method folder without a Method class


def tree_slamrun(tree: Path, *args, cwd: Path) -> subprocess.CompletedProcess:
    """slamrun from the copied tree (first on the path: the installed one is an editable finder, consulted last)."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    return subprocess.run(
        [sys.executable, "-m", "slamrun.cli", *map(str, args)], capture_output=True, text=True, env=env, cwd=cwd,
        timeout=300,
    )  # fmt: skip


@pytest.mark.parametrize("folder", ["no-class", "raises"])
def test_a_method_folder_without_a_method_class_is_named_and_the_others_work(tmp_path, tiny_dataset, folder):
    """helpers/ with an __init__.py and no Method class made list-methods, validate and campaign end in a traceback
    ('declares 0 Method classes named 'helpers'')."""
    tree = tmp_path / "tree"
    shutil.copytree(ROOT / "slamrun", tree / "slamrun", ignore=shutil.ignore_patterns("__pycache__"))
    helpers = tree / "slamrun" / "methods" / "helpers"
    helpers.mkdir()
    if folder == "no-class":
        (helpers / "__init__.py").write_text('"""Helpers several methods share."""\n\n\ndef clamp(x):\n    return x\n')
        says = "declares 0 Method classes named 'helpers'"
    else:
        (helpers / "__init__.py").write_text("raise RuntimeError('half-written')\n")
        says = "RuntimeError: half-written"
    listed = tree_slamrun(tree, "list-methods", cwd=tmp_path)
    assert listed.returncode == 0 and "Traceback" not in listed.stderr, listed.stderr
    (line,) = [line for line in listed.stdout.splitlines() if line.startswith("not registered: helpers:")]
    assert "slamrun/methods/helpers/" in line, line
    assert says in listed.stdout.replace("\n", " "), listed.stdout
    assert "reference_vo" in listed.stdout and "dso" in listed.stdout
    as_json = tree_slamrun(tree, "list-methods", "--json", cwd=tmp_path)
    assert as_json.returncode == 0 and "reference_vo" in json.loads(as_json.stdout), as_json.stderr

    spec = spec_file(tmp_path, tiny_dataset, [fake_method()])
    out = tree_slamrun(tree, "validate", spec, cwd=tmp_path)
    assert out.returncode == 0 and "Traceback" not in out.stderr, out.stderr
    out = tree_slamrun(tree, "campaign", spec, cwd=tmp_path)
    assert out.returncode == 0 and "Traceback" not in out.stderr, out.stdout[-2000:] + out.stderr[-2000:]
    (row,) = ledger_rows(tmp_path / "results")
    assert row["status"] == "done", row

    asks = tmp_path / "asks"
    asks.mkdir()
    out = tree_slamrun(tree, "validate", spec_file(asks, tiny_dataset, [{"name": "helpers"}]), cwd=tmp_path)
    refused(out, "methods[0].name", "slamrun/methods/helpers", says)


# ---------------------------------------------------------------- also seen: a plug-in import that never returns


LIMIT_S = 3


def test_a_plugin_whose_import_hangs_is_given_up_and_the_others_work(tmp_path, tiny_dataset):
    """A plug-in module that sleeps at import blocked list-methods and validate without a time limit."""
    site = tmp_path / "site"
    plugin(site, "sleepy-vo", "sleepy_mod", "sleepy", body="import time\n\ntime.sleep(600)\n")
    plugin(site, "fine-vo", "fine_mod", "fine")  # imports `from slamrun.methods import Method` as the API says
    env = with_site(site, SLAMRUN_PLUGIN_IMPORT_S=str(LIMIT_S))
    bound = LIMIT_S + 25  # the limit, and starting slamrun on a loaded machine

    start = time.monotonic()
    listed = slamrun("list-methods", env=env, timeout=120)
    took = time.monotonic() - start
    assert listed.returncode == 0 and "Traceback" not in listed.stderr, listed.stderr
    assert took < bound, took
    text = listed.stdout.replace("\n", " ")
    assert "not registered: sleepy" in listed.stdout and f"did not return within {LIMIT_S} s" in text, text
    assert "sleepy-vo 0.1" in text
    assert "fine" in listed.stdout and "fine-vo 0.1" in text and "not registered: fine" not in listed.stdout

    spec = spec_file(tmp_path, tiny_dataset, [{"name": "fine"}])
    start = time.monotonic()
    out = slamrun("validate", spec, env=env, timeout=120)
    assert out.returncode == 0, out.stderr
    assert time.monotonic() - start < bound

    asks = tmp_path / "asks"
    asks.mkdir()
    start = time.monotonic()
    out = slamrun("validate", spec_file(asks, tiny_dataset, [{"name": "sleepy"}]), env=env, timeout=120)
    refused(out, "methods[0].name", "sleepy_mod:Good from sleepy-vo 0.1", f"did not return within {LIMIT_S} s")
    assert time.monotonic() - start < bound


@pytest.mark.parametrize("value", ["abc", "0", "-5", "nan"])
def test_a_bad_import_limit_is_named_never_fatal(tmp_path, value):
    site = tmp_path / "site"
    plugin(site, "fine-vo", "fine_mod", "fine")
    listed = slamrun("list-methods", env=with_site(site, SLAMRUN_PLUGIN_IMPORT_S=value), timeout=120)
    assert listed.returncode == 0 and "Traceback" not in listed.stderr, listed.stderr
    text = listed.stdout.replace("\n", " ")
    assert "not registered: fine" in listed.stdout and f"SLAMRUN_PLUGIN_IMPORT_S={value!r}" in text, text
    assert "reference_vo" in listed.stdout
