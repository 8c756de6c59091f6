"""One object owns a run's paths; nobody else joins path strings for a run."""

from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path

from runner.plan import RunKey


@dataclass(frozen=True)
class RunPaths:
    results: Path
    key: RunKey

    @property
    def final(self) -> Path:
        return self.results / self.key.relpath

    def staging(self, attempt: int) -> Path:
        """Where an attempt writes before the rename that makes it complete."""
        return self.final.with_name(f".{self.final.name}.tmp-{attempt}")

    @staticmethod
    def raw(run_dir: Path) -> Path:
        """The method's work directory (its config files and raw outputs)."""
        return run_dir / "raw"

    @staticmethod
    def trajectory(run_dir: Path) -> Path:
        return run_dir / "trajectory.txt"

    @staticmethod
    def log(run_dir: Path) -> Path:
        return run_dir / "log.txt"

    @staticmethod
    def resources(run_dir: Path) -> Path:
        return run_dir / "resources.csv"

    @staticmethod
    def run_json(run_dir: Path) -> Path:
        return run_dir / "run.json"

    def clear_staging(self) -> None:
        """Remove half-written attempts (a crash mid-run leaves them)."""
        parent = self.final.parent
        if parent.exists():
            for p in parent.glob(f".{self.final.name}.tmp-*"):
                shutil.rmtree(p, ignore_errors=True)
