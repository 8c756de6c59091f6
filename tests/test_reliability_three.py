"""Reliability, round three: doors to a user's files, bad data never charged to a method, bounded on hostile
input, and the causes of the flaky tests; each with real processes and files."""

from __future__ import annotations

from pathlib import Path

from slamrun.engine.campaign import run_campaign
from slamrun.engine.spec_file import load_spec
from tests.conftest import fake_method, one_sequence, write_spec
from tests.test_campaign import ledger_rows


def campaign(spec_path: Path, **kw):
    return run_campaign(load_spec(spec_path), log=kw.pop("log", lambda *a: None), **kw)


# ------------------------------------------------------------ 2: a view rebuilt under a run


def test_a_view_prepared_again_while_a_run_reads_it_is_infra_not_the_methods_failure(tmp_path, tiny_dataset):
    """The cache is deleted and the same view prepared again mid-run (the user's `slamrun prepare`): the run that
    lost its input is not charged, even though a whole view of the same content is back in the cache."""
    once = tmp_path / "rebuilt-once"
    spec = write_spec(
        tmp_path,
        tiny_dataset,
        [fake_method("rebuild-view", extra=["--once", str(once)])],
        datasets=one_sequence(tiny_dataset),
        directions=["forward"],
        lanes=1,
    )
    res = campaign(spec)
    rows = ledger_rows(res.results)
    assert once.exists(), "the run did not rebuild the view"
    assert [(r["status"], r["failure"]) for r in rows] == [("done", None)], [(r["status"], r["message"]) for r in rows]
    assert rows[0]["attempts"] == 2  # the first attempt was infra (its view replaced), retried


# ------------------------------------------------------------ 4: bounded on hostile files (the shared guards)


def test_reading_refuses_fifos_devices_and_oversized_files_without_blocking(tmp_path):
    import os

    import pytest

    from slamrun.core.inputs import read_bounded
    from slamrun.errors import DatasetError

    fifo = tmp_path / "frame.png"
    os.mkfifo(fifo)  # nobody writes it: a plain open() would block for ever
    with pytest.raises(DatasetError, match="FIFO"):
        read_bounded(fifo, 2**20, "a frame", DatasetError)
    zero = tmp_path / "zero.png"
    zero.symlink_to("/dev/zero")
    with pytest.raises(DatasetError, match="character device"):
        read_bounded(zero, 2**20, "a frame", DatasetError)
    sparse = tmp_path / "sparse.png"
    with open(sparse, "wb") as fh:
        fh.truncate(2 * 2**30)  # 2 GiB, no block on disk
    with pytest.raises(DatasetError, match="at most"):
        read_bounded(sparse, 64 * 2**20, "a frame", DatasetError)
    small = tmp_path / "ok.txt"
    small.write_bytes(b"12345")
    assert read_bounded(small, 5) == b"12345"


def test_yaml_alias_bombs_and_deep_nesting_are_refused_before_anything_is_built(tmp_path):
    """In a process limited to 1 GiB of address space: the refusal builds nothing."""
    import subprocess
    import sys

    levels = ["a0: &a0 [x, x, x, x, x, x, x, x, x, x]"]
    levels += [f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 10)}]" for i in range(1, 9)]
    bomb = tmp_path / "sensor.yaml"
    bomb.write_text("\n".join(levels) + "\ncamera_model: *a8\n")  # about 1 KB, 10^9 values expanded
    deep = tmp_path / "camchain.yaml"
    deep.write_text("x: " + "[" * 20_000 + "]" * 20_000 + "\n")
    code = """
import resource, sys
resource.setrlimit(resource.RLIMIT_AS, (2**30, resource.RLIM_INFINITY))
from slamrun.core.inputs import load_yaml_file
from slamrun.errors import DatasetError
for path in sys.argv[1:]:
    try:
        load_yaml_file(path, "calibration", DatasetError)
    except DatasetError as exc:
        print(exc)
"""
    out = subprocess.run([sys.executable, "-c", code, str(bomb), str(deep)], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    said = out.stdout.splitlines()
    assert len(said) == 2 and "sensor.yaml: its YAML aliases expand to" in said[0], said
    assert "camchain.yaml: YAML nested too deeply" in said[1], said


def test_a_spec_that_is_a_fifo_is_refused_at_once(tmp_path):
    import os

    import pytest

    from slamrun.errors import SpecError

    spec = tmp_path / "spec.yaml"
    os.mkfifo(spec)
    with pytest.raises(SpecError, match="FIFO"):
        load_spec(spec)


# ------------------------------------------------------------ the machine lacks what the method needs


def test_a_method_that_says_the_machine_lacks_what_it_needs_is_not_charged(tmp_path, tiny_dataset):
    """A GPU method's process that finds too little GPU memory says so (`GPU MEMORY: ...`, its infra_pattern) and
    exits: the run is the machine's failure (retried, then `infra`), never the method's; the same exit without the
    pattern declared is the method's crash."""
    said = fake_method("gpu-memory", label="declares", infra_pattern=r"^(NO GPU|GPU MEMORY):")
    silent = fake_method("gpu-memory", label="silent")
    spec = write_spec(
        tmp_path, tiny_dataset, [said, silent], datasets=one_sequence(tiny_dataset), directions=["forward"], retries=1
    )
    rows = {r["method"]: r for r in ledger_rows(campaign(spec).results)}
    assert (rows["declares"]["status"], rows["declares"]["failure"]) == ("failed", "infra"), rows["declares"]
    assert "GPU MEMORY: needs about 9.9 GiB" in rows["declares"]["message"]
    assert rows["declares"]["attempts"] == 2  # retried once, as infrastructure is
    assert (rows["silent"]["status"], rows["silent"]["failure"]) == ("failed", "crashed"), rows["silent"]
    assert rows["silent"]["attempts"] == 1


def test_a_log_pattern_that_is_no_regular_expression_is_refused_before_any_run(tmp_path, tiny_dataset):
    """An external method's infra_pattern (or its other log patterns) that Python cannot compile is a spec error
    naming the key, before anything runs, not a traceback when a run ends."""
    import pytest

    from slamrun.errors import SpecError

    bad = fake_method("gpu-memory", infra_pattern="^(GPU MEMORY", lost_pattern="[lost")
    spec = write_spec(tmp_path, tiny_dataset, [bad], datasets=one_sequence(tiny_dataset), directions=["forward"])
    with pytest.raises(SpecError) as err:
        load_spec(spec)
    said = "\n".join(err.value.problems)
    assert "methods[0].params.infra_pattern" in said and "not a regular expression" in said, said
    assert "methods[0].params.lost_pattern" in said, said
    assert not (tmp_path / "results").exists()
