"""Inputs that pass the checks and still cannot be read: /proc/self/mem is a regular file of size 0 whose read
fails (EIO), once a traceback in `evaluate`; a results folder whose ledger.sqlite is a folder was read from its
results.csv by `stats` and `report` (every command is to stop with one line naming the ledger)."""

from __future__ import annotations

import shutil
import subprocess
import sys

import pandas as pd

from tests.conftest import SHARED_DATA


def slamrun(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "slamrun.cli", *map(str, args)], capture_output=True, text=True)


def test_evaluate_names_a_file_whose_read_fails(shared_data):
    gt = SHARED_DATA / "evo_test_data" / "fr2_desk_groundtruth.txt"
    out = slamrun("evaluate", "--gt-format", "tum", "--gt", gt, "--json", "/proc/self/mem")
    assert out.returncode == 1 and "Traceback" not in out.stderr, out.stderr
    assert "/proc/self/mem: cannot be read (Input/output error)" in out.stdout
    assert "1 of 1 file(s) could not be evaluated" in out.stderr


def test_stats_and_report_refuse_a_ledger_that_is_a_folder(tmp_path):
    results = tmp_path / "results"
    (results / "ledger.sqlite").mkdir(parents=True)
    pd.DataFrame({"method": ["a", "b"], "ate_rmse": [0.1, 0.2]}).to_csv(results / "results.csv", index=False)
    (results / ".slamrun-results").write_text("")
    for command in ("stats", "report"):
        out = slamrun(command, results)
        assert out.returncode == 1 and "Traceback" not in out.stderr, out.stderr
        assert "ledger.sqlite: not a readable ledger (a folder)" in out.stderr, out.stderr
        assert len(out.stderr.strip().splitlines()) == 1, out.stderr
    assert not (results / "report").exists()
    shutil.rmtree(results)
