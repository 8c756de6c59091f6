"""A results folder may have any legal name: '#', '?' and '%' in it once broke every read-only ledger open (the
file: URI was not encoded), created an empty SQLite file beside the folder and showed 0 runs."""

from __future__ import annotations

import pytest

from slamrun.engine.ledger import Ledger


@pytest.mark.parametrize("name", ["a#b", "run?x=1", "100%", "pct%41", "sp ace&semi;colon"])
def test_a_read_only_open_works_in_a_folder_of_any_name(tmp_path, name):
    folder = tmp_path / name
    ledger = Ledger(folder / "ledger.sqlite")
    ledger.set_meta("campaign", "odd")
    ledger.close()
    before = sorted(p.name for p in tmp_path.rglob("*"))
    reader = Ledger(folder / "ledger.sqlite", read_only=True)
    try:
        assert reader.meta("campaign") == "odd"
    finally:
        reader.close()
    assert sorted(p.name for p in tmp_path.rglob("*")) == before  # nothing created beside or inside


def test_a_campaign_and_status_in_such_a_folder(tiny_dataset, tmp_path):
    import json
    import subprocess
    import sys

    from slamrun.engine.campaign import run_campaign
    from slamrun.engine.spec_file import load_spec
    from tests.conftest import fake_method, one_sequence, write_spec

    results = tmp_path / "res#1?x%41"
    spec = write_spec(
        tmp_path, tiny_dataset, [fake_method()], datasets=one_sequence(tiny_dataset), results=str(results)
    )
    res = run_campaign(load_spec(spec), log=lambda *a: None)
    assert res.results == results
    out = subprocess.run(
        [sys.executable, "-m", "slamrun.cli", "status", str(results), "--json"], capture_output=True, text=True
    )
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout)["done"] == 2  # the one sequence, forward and backward
    assert sorted(p.name for p in tmp_path.iterdir() if p.suffix == ".sqlite" or "%" in p.name) == [results.name]
