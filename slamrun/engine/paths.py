"""One object owns a run's paths; nobody else joins path strings for a run."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
from dataclasses import dataclass
from pathlib import Path

from slamrun.engine.ledger import record_names
from slamrun.engine.plan import RunKey
from slamrun.errors import SlamRunError
from slamrun.results import files
from slamrun.results.vocabulary import is_infra


@dataclass(frozen=True)
class RunPaths:
    results: Path
    key: RunKey

    def __post_init__(self) -> None:
        root = Path(self.results).resolve()
        final = (root / self.key.relpath).resolve()
        if not final.is_relative_to(root / "runs"):
            raise SlamRunError(f"run {self.key.id}: its folder {final} would be outside {root / 'runs'}")

    @property
    def final(self) -> Path:
        return self.results / self.key.relpath

    def token(self, attempt: int) -> str:
        return run_token(self.final, attempt)

    def staging(self, attempt: int) -> Path:
        """Where an attempt writes before the rename that makes it complete."""
        return self.final.with_name(f".{self.final.name}.tmp-{attempt}")

    @staticmethod
    def raw(run_dir: Path) -> Path:
        """The method's work directory (its config files and raw outputs)."""
        return run_dir / "raw"

    @staticmethod
    def trajectory(run_dir: Path) -> Path:
        return run_dir / files.TRAJECTORY

    @staticmethod
    def log(run_dir: Path) -> Path:
        return run_dir / files.LOG

    @staticmethod
    def resources(run_dir: Path) -> Path:
        return run_dir / "resources.csv"

    @staticmethod
    def run_json(run_dir: Path) -> Path:
        return run_dir / files.RUN_RECORD

    def clear_staging(self, up_to: int | None = None) -> None:
        """Remove half-written attempts (a crash mid-run leaves them): those numbered 1 to `up_to`, checked one by
        one (a run's folder has thousands of siblings at the study's scale: listing them for every run made the
        runner's cost per run grow with the campaign), or every one found in the folder when `up_to` is None
        (recovery at a start). Attempts are numbered from the ledger, so a later one never meets an earlier
        one's leftovers."""
        parent = self.final.parent
        if up_to is not None:
            stages = (self.staging(a) for a in range(1, up_to + 1))
        elif parent.exists():
            stages = parent.glob(f".{self.final.name}.tmp-*")
        else:
            return
        for p in stages:
            if os.path.lexists(p):
                shutil.rmtree(p, ignore_errors=True)


def finished_record(run_dir: Path, key: str) -> dict | None:
    """The run.json of a run that finished in `run_dir` (done, or failed by the method's own behaviour), or
    None when the folder holds no complete run of this key."""
    try:
        rec = json.loads(RunPaths.run_json(run_dir).read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(rec, dict) or rec.get("key") != key:
        return None
    rec = record_names(rec)  # a run.json of an earlier version says label, method, state
    if rec.get("status") not in ("done", "failed") or is_infra(rec["status"], rec.get("failure")):
        return None
    return rec


def run_token(run_dir: Path, attempt: int) -> str:
    """The token in the environment of every process of a run's attempt (see backends.local): derived from
    the run's folder, so crash recovery finds the processes of a stale attempt from its ledger row alone."""
    return hashlib.sha256(f"{Path(run_dir).resolve()}|{attempt}".encode()).hexdigest()[:32]
