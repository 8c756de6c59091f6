"""Outputs that scripts can trust: RFC 8259 JSON, a closed pipe ends a command quietly, exit codes that say
whether everything asked for was done."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from slamrun.core import jsonio

SLAMRUN = [sys.executable, "-m", "slamrun.cli"]


def strict_json(text: str):
    """Parses as a strict RFC 8259 parser does: bare NaN / Infinity refused."""

    def refuse(name: str):
        raise ValueError(f"not JSON: {name}")

    return json.loads(text, parse_constant=refuse)


def test_every_non_finite_number_is_null_and_numpy_values_are_plain():
    value = {
        "a": float("nan"),
        "b": [np.float64("inf"), -math.inf, 1.5],
        "c": np.array([1.0, np.nan]),
        "d": np.int64(3),
        "e": np.bool_(True),
        "f": Path("/x"),
        7: (np.float32(2.5),),
    }
    assert strict_json(jsonio.dumps(value)) == {
        "a": None,
        "b": [None, None, 1.5],
        "c": [1.0, None],
        "d": 3,
        "e": True,
        "f": "/x",
        "7": [2.5],
    }


@pytest.mark.parametrize("argv,codes", [(["schema"], (141,)), (["list-methods"], (141,)), (["--help"], (0, 141))])
def test_a_closed_pipe_ends_a_command_quietly(argv, codes, tmp_path):
    """`slamrun schema | head`: the reader is gone before slamrun writes; no traceback, the exit of a Unix tool
    that lost its reader (141; argparse's own --help may end first)."""
    r, w = os.pipe()
    os.close(r)  # the reader went away before the first byte
    try:
        p = subprocess.run(SLAMRUN + argv, stdout=w, stderr=subprocess.PIPE, timeout=60, cwd=tmp_path)
    finally:
        os.close(w)
    assert b"Traceback" not in p.stderr and b"BrokenPipeError" not in p.stderr, p.stderr.decode()
    assert p.returncode in codes, (p.returncode, p.stderr.decode())


def test_verify_exits_1_when_a_method_is_not_verified_names_the_spec_backend_and_writes_where_the_user_works(
    tmp_path,
):
    spec = tmp_path / "spec.yaml"
    spec.write_text(
        "name: vt\nresults: ./res\n"
        "datasets:\n  - {name: s, path: ./data, sequences: [room_a], synthetic: {frames: 30}}\n"
        "methods:\n  - {name: external, label: crashy, params: {argv: [/bin/false]}}\nbackend: local\n"
    )
    p = subprocess.run(
        SLAMRUN + ["verify", str(spec), "--trials", "1", "--frames", "30"],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=tmp_path,
        env={**os.environ, "COLUMNS": "200"},
    )
    assert p.returncode == 1, p.stdout[-2000:] + p.stderr[-2000:]
    assert "(backend: local)" in p.stdout and "backend: docker" not in p.stdout
    table = tmp_path / ".cache" / "verify" / "verify.md"
    assert table.is_file() and "crashy" in table.read_text()
