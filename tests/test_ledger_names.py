"""The ledger names its columns as results.csv does (method: the label, method_name: the registered method, status);
a ledger and a run.json of an earlier version (label, method, state) are read, and a ledger opened to write is
renamed in place, every row kept."""

from __future__ import annotations

import json
import sqlite3

from slamrun.engine.export import COLUMNS, results_frame
from slamrun.engine.ledger import ALL_COLUMNS, Ledger, _coltype, record_names
from slamrun.engine.paths import finished_record

OLD = {"method": "label", "method_name": "method", "status": "state"}  # today's name -> the earlier one


def old_ledger(path) -> None:
    """A ledger as slamrun wrote it before the rename: the same columns and types under the earlier names."""
    cols = ", ".join(f"{OLD.get(c, c)} {_coltype(c)}" for c in ALL_COLUMNS if c != "key")
    with sqlite3.connect(path) as db:
        db.execute(f"CREATE TABLE runs (key TEXT PRIMARY KEY, {cols})")
        db.execute("CREATE TABLE meta (name TEXT PRIMARY KEY, value TEXT)")
        db.execute("CREATE INDEX runs_state ON runs(active, state)")
        db.execute(
            "INSERT INTO runs (key, label, method, dataset, sequence, direction, trial, active, state, attempts, "
            "e_align) VALUES ('k1', 'fast-dso', 'dso', 'd', 's', 'forward', 0, 1, 'done', 1, 0.25)"
        )
        db.execute(
            "INSERT INTO runs (key, label, method, dataset, sequence, direction, trial, active, state, attempts) "
            "VALUES ('k2', 'fast-dso', 'dso', 'd', 's', 'backward', 0, 1, 'pending', 0)"
        )


def test_an_earlier_ledger_is_read_and_renamed_with_every_row(tmp_path):
    path = tmp_path / "ledger.sqlite"
    old_ledger(path)
    before = path.read_bytes()
    ro = Ledger(path, read_only=True)
    rows = ro.rows(columns=("key", "method", "method_name", "status", "e_align"))
    assert ro.counts() == {"pending": 1, "running": 0, "done": 1, "failed": 0}
    assert [r["status"] for r in ro.rows(status="done")] == ["done"]
    ro.close()
    assert path.read_bytes() == before  # reading wrote nothing
    assert rows[0] == {"key": "k1", "method": "fast-dso", "method_name": "dso", "status": "done", "e_align": 0.25}

    ledger = Ledger(path)  # opened to write: renamed in place
    with sqlite3.connect(path) as db:
        names = [row[1] for row in db.execute("PRAGMA table_info(runs)")]
        index = db.execute("SELECT sql FROM sqlite_master WHERE name = 'runs_state'").fetchone()[0]
    assert {"method", "method_name", "status"} <= set(names) and not {"label", "state"} & set(names)
    assert "status" in index
    df = results_frame(ledger)
    assert list(df.columns) == list(COLUMNS)
    assert df.set_index("key").loc["k1", ["method", "method_name", "status"]].tolist() == ["fast-dso", "dso", "done"]
    assert ledger.pending_keys() == ["k2"]
    ledger.close()


def test_an_earlier_run_json_is_read_in_the_ledgers_names(tmp_path):
    record = {"key": "k1", "label": "fast-dso", "method": "dso", "state": "done", "failure": None, "e_align": 0.25}
    (tmp_path / "run.json").write_text(json.dumps(record))
    rec = finished_record(tmp_path, "k1")
    assert rec["method"] == "fast-dso" and rec["method_name"] == "dso" and rec["status"] == "done"
    assert "label" not in rec and "state" not in rec
    new = {"key": "k1", "method": "fast-dso", "method_name": "dso", "status": "done"}
    assert record_names(new) is new
