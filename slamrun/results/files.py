"""The files slamrun writes in a campaign's results folder and in each run's folder, named once: every module reads
them from here (a campaign's through CampaignFiles, a run's through engine.paths.RunPaths)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

LEDGER = "ledger.sqlite"
RESULTS_CSV = "results.csv"
RESULTS_PARQUET = "results.parquet"
ROBUSTNESS_CSV = "robustness.csv"  # the report's robustness figures of every dataset, one row a level
SPEC = "spec.resolved.yaml"  # the spec as run
LOCK = "runner.lock"
MARKER = ".slamrun-results"  # says the folder is slamrun's
REPORT = "report"
RUNS = "runs"
# a run's folder
TRAJECTORY = "trajectory.txt"  # its trajectory in TUM, at the sequence's original timestamps
RUN_RECORD = "run.json"
LOG = "log.txt"


@dataclass(frozen=True)
class CampaignFiles:
    """A campaign's results folder and the files slamrun keeps in it."""

    root: Path

    @property
    def ledger(self) -> Path:
        return Path(self.root) / LEDGER

    @property
    def results_csv(self) -> Path:
        return Path(self.root) / RESULTS_CSV

    @property
    def results_parquet(self) -> Path:
        return Path(self.root) / RESULTS_PARQUET

    @property
    def robustness_csv(self) -> Path:
        return Path(self.root) / ROBUSTNESS_CSV

    @property
    def spec(self) -> Path:
        return Path(self.root) / SPEC

    @property
    def lock(self) -> Path:
        return Path(self.root) / LOCK

    @property
    def report(self) -> Path:
        return Path(self.root) / REPORT

    @property
    def runs(self) -> Path:
        return Path(self.root) / RUNS

    def table(self) -> Path:
        """The results table to read: the Parquet file where there is one, else the CSV."""
        return self.results_parquet if self.results_parquet.exists() else self.results_csv
