"""A read-only open of the ledger (status, serve, report) beside a writer that comes and goes: a writer that
started after the reader looked for its -wal file made a whole ledger read as damaged (immutable=1), about once in
5,000 opens here. The reader now reads again as a reader beside a writer does; never damaged."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

from slamrun.engine.ledger import Ledger

WRITER = """
import sys, time
from slamrun.engine.ledger import Ledger
path, until = sys.argv[1], time.monotonic() + float(sys.argv[2])
i = 0
while time.monotonic() < until:
    ledger = Ledger(path)  # each session: the -wal file appears, grows, and goes at the close
    for k in range(20):
        ledger.set_meta(f"k{k}", "x" * 3000 * (i % 5))
    ledger.set_meta("n", i)
    ledger.close()
    i += 1
print(i)
"""


def test_a_reader_beside_a_writer_that_comes_and_goes_never_reads_a_damaged_ledger(tmp_path):
    path = tmp_path / "ledger.sqlite"
    Ledger(path).close()
    writer = subprocess.Popen(
        [sys.executable, "-c", WRITER, str(path), "10"], stdout=subprocess.PIPE, text=True, cwd=Path.cwd()
    )
    reads, errors = 0, []
    end = time.monotonic() + 10
    try:
        while time.monotonic() < end:
            try:
                ledger = Ledger(path, read_only=True)
                ledger.meta("n")
                ledger.close()
                reads += 1
            except Exception as exc:  # noqa: BLE001 - every failure counted, none expected
                errors.append(repr(exc)[:300])
    finally:
        sessions = int(writer.communicate(timeout=60)[0])
    assert sessions > 50 and reads > 500, (sessions, reads)
    assert errors == [], f"{len(errors)} of {reads + len(errors)} reads failed: {errors[:3]}"
