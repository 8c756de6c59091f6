"""A campaign's session: who runs it now (the record kept in the ledger's meta table), whether that process still
lives, and the campaign's figures read from its ledger without writing or locking anything (`slamrun status`, the
live view's periodic read). Light on imports: `slamrun status` loads this, the ledger and the figures only."""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING

from slamrun.engine.ledger import Ledger
from slamrun.engine.progress import Figures, Tracker
from slamrun.engine.spec import RecordedSpec
from slamrun.results.files import CampaignFiles

if TYPE_CHECKING:
    from slamrun.engine.spec import CampaignSpec


def session_record(spec: CampaignSpec) -> dict:
    """Who runs the campaign now, since when, on how many lanes (for status, --watch and the ETA)."""
    import psutil

    me = psutil.Process()
    lanes = 1 if spec.measurement == "exclusive" else spec.lanes
    return {"pid": me.pid, "pid_start": me.create_time(), "started_at": time.time(), "lanes": lanes, "ended_at": None}


def session_alive(session: dict | None) -> bool:
    """Whether the campaign process of a session record still runs (same PID and start time)."""
    import psutil

    if not session or session.get("ended_at"):
        return False
    try:
        return abs(psutil.Process(session["pid"]).create_time() - session["pid_start"]) < 0.01
    except (psutil.Error, KeyError, TypeError):
        return False


def read_tracker(results: Path) -> Tracker | None:
    """A Tracker over a results folder's ledger (rows, session, campaign name), read without writing or locking
    anything; None when the ledger does not exist yet. A session whose process is gone is shown as ended."""
    path = CampaignFiles(Path(results)).ledger
    if not path.exists():
        return None
    ledger = Ledger(path, read_only=True)
    try:
        return tracker_of(ledger, Path(results).name)
    finally:
        ledger.close()


def tracker_of(ledger: Ledger, name: str) -> Tracker:
    """A Tracker over an open ledger's active runs; `name` when the ledger does not record its campaign's."""
    return Tracker(ledger.progress_rows(), current_session(ledger), ledger.meta("campaign", name))


def current_session(ledger: Ledger) -> dict | None:
    """The ledger's session record; one whose process is gone is shown as ended (crashed)."""
    session = ledger.meta("session")
    if session and not session.get("ended_at") and not session_alive(session):
        session = {**session, "ended_at": session.get("last_seen") or session["started_at"], "crashed": True}
    return session


def read_figures(results: Path, now: float | None = None) -> Figures | None:
    """The figures of a results folder's ledger, read without writing or locking anything; None when the
    ledger does not exist yet."""
    tracker = read_tracker(results)
    return None if tracker is None else tracker.figures(now or time.time())


def measurement_conditions(recorded: object) -> str:
    """How the runs shared the machine, as the recorded spec said: one at a time (exclusive), or N lanes side by
    side."""
    spec = RecordedSpec.read(recorded)
    if spec is None:
        return ""
    if spec.measurement == "exclusive":
        return "exclusive: one run at a time, every CPU of the runner"
    lanes, per = spec.lanes, spec.cpus_per_lane
    where = ", on a Dask cluster's workers" if spec.distributed else ""
    cpus = f" of {per} CPU(s) each" if per else " (the runner's CPUs split between them)"
    return f"parallel: {lanes} lane(s){cpus} side by side{where}"
