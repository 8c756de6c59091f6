"""Expand a spec into runs with stable keys."""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

import slamrun.methods
from slamrun.core.metrics import RpeInterval
from slamrun.datasets.layouts import sequence_identity
from slamrun.datasets.view import Direction, Profile
from slamrun.engine.spec import CampaignSpec, MethodSpec


@dataclass(frozen=True)
class RunKey:
    """(method label, sequence and its data, direction, trial, settings hash): the ledger's primary key."""

    label: str
    sequence: str
    direction: Direction
    trial: int
    settings: str  # hash of the settings that change results
    data: str = "none"  # digest of the sequence's content (slamrun.datasets.tum_mono.sequence_identity)

    @property
    def id(self) -> str:
        return f"{self.label}@{self.settings}/{self.sequence}@{self.data}/{self.direction.value}/{self.trial:02d}"

    @property
    def relpath(self) -> Path:
        """runs/<label>@<settings>/<sequence>@<data>/<direction>/<trial>: new settings or new data never reuse a
        folder."""
        return (
            Path("runs")
            / f"{self.label}@{self.settings}"
            / f"{self.sequence}@{self.data}"
            / self.direction.value
            / f"{self.trial:02d}"
        )


@dataclass(frozen=True)
class PlannedRun:
    key: RunKey
    method_index: int  # into spec.methods
    method: str  # registry name
    dataset: str
    sequence_dir: Path
    profile: Profile
    timeout_s: float
    metrics: tuple[str, ...] = ("tum-mono",)  # the dataset's metrics
    alignment: str = "sim3"
    rpe: RpeInterval = RpeInterval()  # the dataset's RPE interval
    min_coverage: float | None = None  # under it, a run is lost


def settings_hash(m: MethodSpec) -> str:
    """Hash of what changes a method's results: its name, its (validated, defaulted) parameters, and for a plug-in
    the distribution and version that provide it (another package or release under the same name is another
    implementation: its runs are never pooled with these)."""
    cls = slamrun.methods.get(m.name)
    params = cls.Params.model_validate(m.params).model_dump(mode="json")
    settings: dict = {"method": m.name, "params": params}
    if (provider := slamrun.methods.PLUGINS.get(m.name)) is not None:
        settings["provider"] = [provider.distribution, provider.version]
    blob = json.dumps(settings, sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()[:10]


def plan(spec: CampaignSpec) -> list[PlannedRun]:
    """Every run of the campaign, trials outermost so a partial campaign covers all methods evenly."""
    runs: list[tuple[tuple, PlannedRun]] = []
    for mi, m in enumerate(spec.methods):
        cls = slamrun.methods.get(m.name)
        method = cls(m.params)
        h = settings_hash(m)
        trials = m.trials or spec.trials
        directions = m.directions or spec.directions
        for ds in spec.datasets:
            for seq in ds.sequences:
                data = sequence_identity(ds.path / seq)
                for direction in directions:
                    for trial in range(trials):
                        key = RunKey(m.run_label, seq, direction, trial, h, data)
                        run = PlannedRun(
                            key,
                            mi,
                            m.name,
                            ds.name,
                            ds.path / seq,
                            method.profile,
                            m.timeout_s or spec.timeout_s,
                            tuple(ds.metrics),
                            ds.alignment,
                            ds.rpe_interval,
                            ds.min_coverage,
                        )
                        runs.append(((trial, mi, seq, direction.value), run))
    runs.sort(key=lambda r: r[0])
    return [r for _, r in runs]
