"""Expand a spec into runs with stable keys."""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from itertools import product
from pathlib import Path

import slamrun.methods
from slamrun.core.metrics import RpeInterval
from slamrun.datasets.layouts import sequence_identity
from slamrun.datasets.perturb import BASELINE, NONE, Perturbation
from slamrun.datasets.view import Direction, Profile
from slamrun.engine.spec import CampaignSpec, DatasetSpec, MethodSpec


@dataclass(frozen=True)
class RunKey:
    """(method label, sequence and its data, direction, perturbation, trial, settings hash): the ledger's primary
    key. A baseline run's key has no perturbation part (keys and folders of campaigns without the axis unchanged)."""

    label: str
    sequence: str
    direction: Direction
    trial: int
    settings: str  # hash of the settings that change results
    data: str = "none"  # digest of the sequence's content (slamrun.datasets.tum_mono.sequence_identity)
    perturbation: str = NONE  # its label (slamrun.datasets.perturb.Perturbation.label)

    @property
    def played(self) -> str:
        """How the sequence was played: `forward`, or `forward+gaussian_noise-5` for a perturbed view."""
        return self.direction.value if self.perturbation == NONE else f"{self.direction.value}+{self.perturbation}"

    @property
    def id(self) -> str:
        return f"{self.label}@{self.settings}/{self.sequence}@{self.data}/{self.played}/{self.trial:02d}"

    @property
    def relpath(self) -> Path:
        """runs/<label>@<settings>/<sequence>@<data>/<direction>[+<perturbation>]/<trial>: new settings or new data
        never reuse a folder."""
        return (
            Path("runs")
            / f"{self.label}@{self.settings}"
            / f"{self.sequence}@{self.data}"
            / self.played
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
    perturbation: Perturbation = BASELINE  # how its view's frames were made worse (none: the ordinary view)

    @property
    def view_key(self) -> tuple[str, Direction, Profile, Perturbation]:
        """The prepared view it runs on (slamrun.engine.preparer)."""
        return (str(self.sequence_dir), self.key.direction, self.profile, self.perturbation)


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


def perturbations(spec: CampaignSpec, ds: DatasetSpec) -> list[Perturbation]:
    """The baseline, then each level of the dataset's perturbations (the campaign's unless it names its own)."""
    chosen = spec.perturbations if ds.perturbations is None else ds.perturbations
    levels = [Perturbation(p.kind, level, spec.perturbation_seed) for p in chosen for level in p.levels]
    return [BASELINE, *dict.fromkeys(levels)]


def plan(spec: CampaignSpec) -> list[PlannedRun]:
    """Every run of the campaign, trials outermost so a partial campaign covers all methods evenly, and within a
    trial the baseline before the perturbed views."""
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
                for direction, pert, trial in product(directions, perturbations(spec, ds), range(trials)):
                    key = RunKey(m.run_label, seq, direction, trial, h, data, pert.label)
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
                        pert,
                    )
                    runs.append(((trial, pert.label != NONE, mi, seq, direction.value, pert.label), run))
    runs.sort(key=lambda r: r[0])
    return [r for _, r in runs]
