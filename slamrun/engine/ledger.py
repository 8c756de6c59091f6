"""The ledger: one SQLite row per run, the campaign's truth. WAL mode, safe to read while a runner writes."""

from __future__ import annotations

import fcntl
import json
import os
import shutil
import sqlite3
import stat
import threading
import time
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING
from urllib.parse import quote

from slamrun.errors import LedgerLockedError, LedgerLostError, SlamRunError, StorageError
from slamrun.results.catalogue import CATALOGUE, CPU_WAIT_PCT, METRIC_COLUMNS, RESOURCE_COLUMNS, WALL_S
from slamrun.results.files import CampaignFiles
from slamrun.results.vocabulary import IMPORTED, STATES

if TYPE_CHECKING:
    from slamrun.engine.plan import PlannedRun

KEY_COLUMNS = (
    "key",
    "method",  # the method's label in the spec (its name, or the label given): what every view calls it
    "method_name",  # the registered method that ran (or `imported`)
    "dataset",
    "sequence",
    "direction",
    "trial",
    "settings",
    "perturbation",
    "level",
)
STATE_COLUMNS = (
    "active",
    "status",
    "attempts",
    "failure",
    "message",
    "exit_code",
    "eval_status",
    "started_at",
    "ended_at",
    "pid",
    "pid_start",
    "run_dir",
    "host",  # the machine that ran it (its run.json: CPU, GPUs, Slurm node)
    "packages",  # a native method's Python packages and versions
    "contended_attempts",  # attempts lost while waiting for a CPU (the machine's load): retried, never charged
    "contended_message",  # the last of them: its wait and the machine's pressure
    "method_failure",  # the failure its process left, before its evaluation decided (re-evaluation starts there)
    "eval_settings",  # the evaluation settings its figures were made with (engine.run_evaluation.EvalSettings.text)
    "slamrun_commit",  # the code that ran it: slamrun's git commit, '+' when its tree had changes
)
ALL_COLUMNS = KEY_COLUMNS + STATE_COLUMNS + METRIC_COLUMNS + RESOURCE_COLUMNS

_TYPES = {  # the ledger's own columns; the results' types are the catalogue's
    "trial": "INTEGER",
    "active": "INTEGER",
    "attempts": "INTEGER",
    "contended_attempts": "INTEGER",
    "exit_code": "INTEGER",
    "pid": "INTEGER",
    "level": "REAL",
    "started_at": "REAL",
    "ended_at": "REAL",
    "pid_start": "REAL",
    **{c.name: c.type for c in CATALOGUE.values()},
}


def _coltype(c: str) -> str:
    return _TYPES.get(c, "TEXT")


# The columns a ledger of an earlier version names otherwise (before 2026-11-29 the ledger said label, method and
# state where results.csv says method, method_name and status): renamed in this order when it is opened to write,
# seen through a view of the new names when it is only read.
RENAMED = (("method", "method_name"), ("label", "method"), ("state", "status"))


def record_names(rec: dict) -> dict:
    """A run's record (run.json, a ledger row) in the ledger's names, whichever version wrote it."""
    if "label" not in rec and "state" not in rec:
        return rec
    out = {k: v for k, v in rec.items() if k not in ("label", "state", "method")}
    if "label" in rec:
        out |= {"method": rec["label"], "method_name": rec.get("method")}
    elif "method" in rec:
        out["method"] = rec["method"]
    if "state" in rec:
        out["status"] = rec["state"]
    return out


def _columns(db: sqlite3.Connection) -> list[str]:
    return [row[1] for row in db.execute("PRAGMA main.table_info(runs)")]


def _rename_columns(db: sqlite3.Connection) -> None:
    """A ledger of an earlier version takes the names results.csv gives its columns (one transaction)."""
    if "label" not in _columns(db):
        return
    db.execute("BEGIN IMMEDIATE")
    try:
        for old, new in RENAMED:
            db.execute(f"ALTER TABLE runs RENAME COLUMN {old} TO {new}")
        db.execute("COMMIT")
    except BaseException:
        db.execute("ROLLBACK")
        raise


def _renamed_view(db: sqlite3.Connection) -> None:
    """A ledger of an earlier version opened read-only: a temporary view (of this connection only, nothing written)
    names its columns as the ledger now does."""
    have = _columns(db)
    if "label" not in have:
        return
    new = dict((old, n) for old, n in RENAMED)
    select = ", ".join(f"{c} AS {new[c]}" if c in new else c for c in have)
    db.execute(f"CREATE TEMP VIEW runs AS SELECT {select} FROM main.runs")


FULL_BELOW_BYTES = 1 << 20  # free space under which a ledger SQLite cannot open is a full disk, not damage


class LedgerDamaged(SlamRunError):
    """The ledger file is not a readable SQLite database (overwritten, truncated, a folder)."""


def damaged_ledger(path: Path, why: str) -> LedgerDamaged:
    """The one error every command gives for a ledger it cannot read, with what to do."""
    return LedgerDamaged(
        f"{path}: not a readable ledger ({why}): damaged, or not slamrun's; move it aside (mv {path} "
        f"{path}.damaged) and run `slamrun campaign SPEC` again: every finished run is imported from its folder "
        "under runs/ into a new ledger, nothing is redone"
    )


def unreadable_ledger(path: Path, why: str) -> SlamRunError:
    """The error for a ledger SQLite cannot open or check: a full disk (SQLite says "disk I/O error" when it cannot
    make the -shm file beside a whole ledger) is said as a full disk, anything else as a damaged ledger."""
    try:
        full = shutil.disk_usage(path.parent).free < FULL_BELOW_BYTES
    except OSError:
        full = False
    if full:
        return StorageError(
            f"{path}: cannot open the ledger: the disk is full ({why}); make room and run the command again (the "
            "ledger and every finished run are kept as they are)"
        )
    return damaged_ledger(path, why)


def _not_a_file(path: Path) -> str | None:
    """Why an existing ledger path is no regular file (a folder, a FIFO, a device), or None. Never blocks."""
    mode = os.stat(path).st_mode
    return None if stat.S_ISREG(mode) else "a folder" if stat.S_ISDIR(mode) else "not a regular file"


def campaign_name(path: Path) -> str | None:
    """The campaign name a ledger records (None when it records none); LedgerDamaged when it cannot be read."""
    ledger = Ledger(path, read_only=True)
    try:
        name = ledger.meta("campaign")
    finally:
        ledger.close()
    return name if isinstance(name, str) else None


def campaign_owner_problem(results: Path, name: str) -> str | None:
    """Why campaign `name` may not write into `results`, or None: a results folder belongs to the campaign that made
    it (the name in its ledger); another spec with the same folder would take over its results.csv and report."""
    ledger = CampaignFiles(results).ledger
    if not ledger.exists():
        return None
    try:
        owner = campaign_name(ledger)
    except SlamRunError as exc:  # a damaged ledger: its own message says what to do
        return str(exc)
    if owner is None or owner == name:
        return None
    return (
        f"{results} holds the results of campaign {owner!r}, and this spec is campaign {name!r}: a results folder "
        f"belongs to one campaign. Give this spec a results folder of its own (`results:` or --results), or name it "
        f"{owner!r} to go on with that campaign"
    )


class ResultsLock:
    """An exclusive lock on a results directory, naming the holder's PID to whoever else asks."""

    def __init__(self, results: Path):
        self.path = CampaignFiles(results).lock
        self._fh = None

    def acquire(self) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        fh = open(self.path, "a+")
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            fh.seek(0)
            holder = fh.read().strip() or "unknown"
            fh.close()
            raise LedgerLockedError(
                f"{self.path.parent}: another slamrun (PID {holder}) is running this campaign; "
                "wait for it or stop it first"
            ) from None
        fh.seek(0)
        fh.truncate()
        fh.write(str(os.getpid()))
        fh.flush()
        self._fh = fh

    def release(self) -> None:
        if self._fh is not None:
            fcntl.flock(self._fh, fcntl.LOCK_UN)
            self._fh.close()
            self._fh = None

    def __enter__(self) -> ResultsLock:
        self.acquire()
        return self

    def __exit__(self, *exc) -> None:
        self.release()


class Ledger:
    def __init__(self, path: Path, read_only: bool = False):
        """The ledger at `path`, created when missing; `read_only` opens an existing one without writing or
        locking anything (for status while a campaign runs)."""
        self.path = Path(path)
        self.read_only = read_only
        self._lock = threading.Lock()
        if read_only:
            if not self.path.exists():
                raise SlamRunError(f"{self.path}: no ledger; is this a results directory of `slamrun campaign`?")
            if why := _not_a_file(self.path):
                raise damaged_ledger(self.path, why)
            # Without a -wal file no process writes it now: `immutable` then reads without creating the -shm
            # and -wal files a read-only open of a WAL database would otherwise leave behind.
            wal = Path(f"{self.path}-wal")
            writer = wal.exists()
            try:
                try:
                    self._open_read_only(immutable=not writer)
                except LedgerDamaged:
                    if writer:
                        raise
                    # `immutable` reads the file as if no one wrote it: a writer that started after the -wal was
                    # looked for makes a whole ledger look damaged. Read again as a reader beside a writer does.
                    self._open_read_only(immutable=False)
            except sqlite3.OperationalError as exc:
                # A full disk: no -shm can be made beside it. A -wal holding nothing (left by a writer that could
                # not start) hides no commit, so the file alone is read exactly; else the disk is said full.
                if not (isinstance(unreadable_ledger(self.path, str(exc)), StorageError) and writer):
                    raise
                if wal.stat().st_size:
                    raise unreadable_ledger(self.path, str(exc)) from None
                self._open_read_only(immutable=True)
            self._inode = os.stat(self.path).st_ino
            return
        self.path.parent.mkdir(parents=True, exist_ok=True)
        if self.path.exists() and (why := _not_a_file(self.path)):
            raise damaged_ledger(self.path, why)
        try:
            self._db = sqlite3.connect(self.path, check_same_thread=False, timeout=30, isolation_level=None)
            self._db.execute("PRAGMA journal_mode=WAL")
            self._db.execute("PRAGMA synchronous=NORMAL")
        except sqlite3.DatabaseError as exc:
            raise unreadable_ledger(self.path, str(exc)) from None
        self._check_whole()
        self._db.row_factory = sqlite3.Row
        cols = ", ".join(f"{c} {_coltype(c)}" for c in ALL_COLUMNS if c != "key")
        self._inode = os.stat(self.path).st_ino
        with self._lock:
            self._db.execute(f"CREATE TABLE IF NOT EXISTS runs (key TEXT PRIMARY KEY, {cols})")
            _rename_columns(self._db)
            have = {row[1] for row in self._db.execute("PRAGMA table_info(runs)")}
            for c in ALL_COLUMNS:  # a ledger of an earlier version gets the columns added since
                if c not in have:
                    self._db.execute(f"ALTER TABLE runs ADD COLUMN {c} {_coltype(c)}")
            self._db.execute("CREATE TABLE IF NOT EXISTS meta (name TEXT PRIMARY KEY, value TEXT)")
            self._db.execute("CREATE INDEX IF NOT EXISTS runs_state ON runs(active, status)")

    def _open_read_only(self, immutable: bool) -> None:
        mode = "mode=ro&immutable=1" if immutable else "mode=ro"
        uri = f"file:{quote(str(self.path.absolute()))}?{mode}"  # '#', '?' and '%' in a folder's name encoded
        self._db = sqlite3.connect(uri, uri=True, check_same_thread=False, timeout=30)
        self._db.row_factory = sqlite3.Row
        try:
            self._check_whole()
        except sqlite3.OperationalError:
            self._db.close()
            raise
        _renamed_view(self._db)

    def _check_whole(self) -> None:
        """LedgerDamaged (closed) when SQLite finds the file is no database or a damaged one (overwritten,
        truncated): every reader and writer gets the same one line instead of an error from deep in a query."""
        try:
            found = [row[0] for row in self._db.execute("PRAGMA quick_check(3)").fetchall()]
        except sqlite3.OperationalError:
            raise  # locked, busy, cannot open: not a damaged file
        except sqlite3.DatabaseError as exc:
            self._db.close()
            raise unreadable_ledger(self.path, str(exc)) from None
        if found != ["ok"]:
            self._db.close()
            raise damaged_ledger(self.path, "; ".join(found)[:300])

    def close(self) -> None:
        self._db.close()

    # ------------------------------------------------------------ writing
    def set_meta(self, name: str, value) -> None:
        with self._lock:
            self._db.execute("INSERT OR REPLACE INTO meta VALUES (?, ?)", (name, json.dumps(value)))

    def meta(self, name: str, default=None):
        try:
            row = self._db.execute("SELECT value FROM meta WHERE name = ?", (name,)).fetchone()
        except sqlite3.OperationalError:  # an empty ledger opened read-only has no tables yet
            return default
        return json.loads(row[0]) if row else default

    def sync_plan(self, runs: Iterable[PlannedRun]) -> int:
        """Insert planned runs not yet in the ledger as pending; mark exactly the plan's runs active.

        Finished runs are never touched; returns how many runs were added.
        """
        rows = [
            (
                r.key.id,
                r.key.label,
                r.method,
                r.dataset,
                r.key.sequence,
                r.key.direction.value,
                r.key.trial,
                r.key.settings,
                r.perturbation.name,
                r.perturbation.level,
            )
            for r in runs
        ]
        with self._lock, self._db:
            self._db.execute("BEGIN")
            before = self._db.execute("SELECT COUNT(*) FROM runs").fetchone()[0]
            self._db.execute("UPDATE runs SET active = 0 WHERE method_name IS NOT ?", (IMPORTED,))  # imports stay
            self._db.executemany(
                "INSERT OR IGNORE INTO runs (key, method, method_name, dataset, sequence, direction, trial, settings, "
                "perturbation, level, active, status, attempts) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, 1, 'pending', 0)",
                rows,
            )
            self._db.executemany("UPDATE runs SET active = 1 WHERE key = ?", [(r[0],) for r in rows])
            after = self._db.execute("SELECT COUNT(*) FROM runs").fetchone()[0]
        return after - before

    def stale_running(self) -> list[sqlite3.Row]:
        return self._db.execute("SELECT * FROM runs WHERE status = 'running'").fetchall()

    def reset_to_pending(self, key: str, keep_attempts: bool = True) -> None:
        with self._lock:
            self._db.execute(
                "UPDATE runs SET status = 'pending', pid = NULL, pid_start = NULL"
                + ("" if keep_attempts else ", attempts = 0, failure = NULL, message = NULL")
                + " WHERE key = ?",
                (key,),
            )

    def reset_infra_failures(self) -> int:
        """Infrastructure failures are not results: a new campaign start tries them again."""
        with self._lock:
            cur = self._db.execute(
                "UPDATE runs SET status = 'pending', attempts = 0, failure = NULL, message = NULL "
                "WHERE status = 'failed' AND failure IN ('infra', 'contended')"
            )
            return cur.rowcount

    def check_present(self) -> None:
        """LedgerLostError when the ledger file is no longer the one this object writes (deleted or replaced)."""
        try:
            same = os.stat(self.path).st_ino == self._inode
        except FileNotFoundError:
            same = False
        if not same:
            raise LedgerLostError(
                f"{self.path} vanished during the campaign (deleted or replaced); no new run was started. The "
                f"finished runs are safe in {self.path.parent / 'runs'}: run the same command again and they are "
                "imported into a new ledger"
            )

    def mark_running(self, key: str, run_dir: str) -> int:
        """Mark a run started; returns its attempt number (1-based). LedgerLostError when the file vanished."""
        self.check_present()
        with self._lock:
            self._db.execute(
                "UPDATE runs SET status = 'running', attempts = attempts + 1, started_at = ?, "
                "ended_at = NULL, run_dir = ? WHERE key = ?",
                (time.time(), run_dir, key),
            )
            return self._db.execute("SELECT attempts FROM runs WHERE key = ?", (key,)).fetchone()[0]

    def note_contended(self, key: str, message: str) -> None:
        """One more attempt of the run lost under contention (retried or recorded `contended`): counted, its
        message kept, whatever the run's final state."""
        with self._lock:
            self._db.execute(
                "UPDATE runs SET contended_attempts = COALESCE(contended_attempts, 0) + 1, contended_message = ? "
                "WHERE key = ?",
                (message[-2000:], key),
            )

    def set_process(self, key: str, pid: int, pid_start: float) -> None:
        with self._lock:
            self._db.execute("UPDATE runs SET pid = ?, pid_start = ? WHERE key = ?", (pid, pid_start, key))

    def finish(self, key: str, status: str, values: dict) -> None:
        """Record a finished run (done or failed) with its metrics and resources, in one statement."""
        if status not in ("done", "failed"):
            raise ValueError(status)
        values = {k: v for k, v in record_names(values).items() if k in ALL_COLUMNS and k not in KEY_COLUMNS}
        values.update(status=status, ended_at=values.get("ended_at") or time.time(), pid=None, pid_start=None)
        sets = ", ".join(f"{k} = ?" for k in values)
        with self._lock:
            self._db.execute(f"UPDATE runs SET {sets} WHERE key = ?", (*values.values(), key))

    def insert_finished(self, records: list[dict]) -> None:
        """Insert finished runs that no plan made (imported ones), all or none, active; existing keys are left
        as they are."""
        with self._lock, self._db:
            self._db.execute("BEGIN")
            for rec in records:
                values = {k: v for k, v in record_names(rec).items() if k in ALL_COLUMNS}
                values.update(active=1, pid=None, pid_start=None)
                cols = ", ".join(values)
                marks = ", ".join("?" for _ in values)
                self._db.execute(f"INSERT OR IGNORE INTO runs ({cols}) VALUES ({marks})", tuple(values.values()))

    # ------------------------------------------------------------ reading
    def rows(
        self, active_only: bool = True, status: str | None = None, columns: tuple[str, ...] | None = None
    ) -> list[dict]:
        """The runs as dicts, in key order: every column, or only `columns` (those a ledger of an earlier version,
        opened read-only, lacks are left out)."""
        if columns:
            have = {row[1] for row in self._db.execute("PRAGMA table_info(runs)")}
            columns = tuple(c for c in columns if c in have) or ("key",)
        sql = f"SELECT {', '.join(columns) if columns else '*'} FROM runs"
        cond, args = [], []
        if active_only:
            cond.append("active = 1")
        if status:
            cond.append("status = ?")
            args.append(status)
        if cond:
            sql += " WHERE " + " AND ".join(cond)
        try:
            return [dict(r) for r in self._db.execute(sql + " ORDER BY key", args).fetchall()]
        except sqlite3.OperationalError:  # an empty ledger opened read-only has no tables yet
            return []

    PROGRESS_COLUMNS = (
        "key", "method", "dataset", "sequence", "direction", "perturbation", "level", "status", "failure", WALL_S,
        "started_at", CPU_WAIT_PCT,
    )  # fmt: skip

    def progress_rows(self) -> list[dict]:
        """The active runs with only what the progress figures read (slamrun.engine.progress.Tracker)."""
        return self.rows(columns=self.PROGRESS_COLUMNS)

    def get(self, key: str) -> dict | None:
        row = self._db.execute("SELECT * FROM runs WHERE key = ?", (key,)).fetchone()
        return dict(row) if row else None

    def pending_keys(self) -> list[str]:
        return [r[0] for r in self._db.execute("SELECT key FROM runs WHERE active = 1 AND status = 'pending'")]

    def counts(self) -> dict[str, int]:
        out = dict.fromkeys(STATES, 0)
        for status, n in self._db.execute("SELECT status, COUNT(*) FROM runs WHERE active = 1 GROUP BY status"):
            out[status] = n
        return out
