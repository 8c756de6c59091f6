"""Expand a spec into runs with stable keys."""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from itertools import product
from pathlib import Path

import slamrun.methods
from slamrun.datasets.layouts import sequence_identity
from slamrun.datasets.perturb import BASELINE, NONE, Perturbation
from slamrun.datasets.view import Direction, Profile
from slamrun.engine.run_evaluation import EvalSettings
from slamrun.engine.spec import CampaignSpec, DatasetSpec, MethodSpec
from slamrun.methods.declare import ADDED


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
    evaluation: EvalSettings = EvalSettings()  # the dataset's metrics, alignment, RPE interval, thresholds
    perturbation: Perturbation = BASELINE  # how its view's frames were made worse (none: the ordinary view)
    seed: int | None = None  # its method's seed for this trial (trial_seed), where the spec does not fix one

    @property
    def view_key(self) -> tuple[str, Direction, Profile, Perturbation]:
        """The prepared view it runs on (slamrun.engine.preparer)."""
        return (str(self.sequence_dir), self.key.direction, self.profile, self.perturbation)


def settings_hash(m: MethodSpec, campaign_seed: int = 0) -> str:
    """Hash of what changes a method's results: its name, its (validated, defaulted) parameters, the campaign's seed
    where its trials' seeds are derived from it, and for a plug-in the distribution and version that provide it
    (another package or release under the same name is another implementation: its runs are never pooled with
    these)."""
    cls = slamrun.methods.get(m.name)
    params = cls.Params.model_validate(m.params).model_dump(mode="json")
    settings: dict = {"method": m.name, "params": hashed(cls.Params, params)}
    if derives_seed(cls, params):
        settings["seeds"] = f"per trial from campaign seed {campaign_seed}"
    if (provider := slamrun.methods.PLUGINS.get(m.name)) is not None:
        settings["provider"] = [provider.distribution, provider.version]
    blob = json.dumps(settings, sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()[:10]


def hashed(model: type, params: dict) -> dict:
    """The parameters that name a configuration: all of them, except that a parameter added to a method after runs
    were made (Field(json_schema_extra={"added": DATE})) is left out while it has its default, which is how those runs
    ran: adding a setting never renames, and so never re-runs, what was made before it."""
    fields = model.model_fields
    return {
        k: v
        for k, v in params.items()
        if not (k in fields and ADDED in (fields[k].json_schema_extra or {}) and v == fields[k].get_default())
    }


def derives_seed(cls, params: dict) -> bool:
    """Whether a method's trials take seeds derived per trial: it takes a seed and its params do not fix one."""
    return bool(cls.seed_param) and params.get(cls.seed_param) is None


def trial_seed(campaign_seed: int, trial: int) -> int:
    """A trial's seed for a method that takes one: from the campaign's seed and the trial alone (the same on any
    machine, different per trial), 31 bits."""
    digest = hashlib.sha256(f"slamrun trial seed {campaign_seed} {trial}".encode()).digest()
    return int.from_bytes(digest[:4], "big") >> 1


def seed_warnings(spec: CampaignSpec) -> list[str]:
    """Each method whose trials will be copies (deterministic: with the seed the spec fixes, or with no seed that
    changes its result), named with what that means: its trials are counted once."""
    out = []
    for m in spec.methods:
        cls = slamrun.methods.get(m.name)
        trials = m.trials or spec.trials
        params = cls.Params.model_validate(m.params).model_dump(mode="json")
        if trials < 2 or not cls.deterministic or derives_seed(cls, params):
            continue
        if cls.seed_param:
            seed = cls.seed_param
            why = f"its seed fixed at {params[seed]} by the spec; drop params.{seed} for a seed per trial"
        else:
            why = "no seed changes its result"
        out.append(
            f"{m.run_label}: its {trials} trials will be identical (deterministic, {why}); trials are counted once"
        )
    return out


def perturbations(spec: CampaignSpec, ds: DatasetSpec) -> list[Perturbation]:
    """The baseline, then each level of the dataset's perturbations (the campaign's unless it names its own)."""
    chosen = spec.perturbations if ds.perturbations is None else ds.perturbations
    seed = spec.perturbation_seed
    levels = [
        Perturbation(p.perturbation_kind, lv, seed, p.schedule, p.draws == "fixed") for p in chosen for lv in p.levels
    ]
    return [BASELINE, *dict.fromkeys(levels)]


def plan(spec: CampaignSpec) -> list[PlannedRun]:
    """Every run of the campaign, trials outermost so a partial campaign covers all methods evenly, and within a
    trial the baseline before the perturbed views."""
    runs: list[tuple[tuple, PlannedRun]] = []
    for mi, m in enumerate(spec.methods):
        cls = slamrun.methods.get(m.name)
        method = cls(m.params)
        h = settings_hash(m, spec.seed)
        seeded = derives_seed(cls, method.params.model_dump(mode="json"))
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
                        ds.evaluation,
                        pert,
                        trial_seed(spec.seed, trial) if seeded else None,
                    )
                    runs.append(((trial, pert.label != NONE, mi, seq, direction.value, pert.label), run))
    runs.sort(key=lambda r: r[0])
    return [r for _, r in runs]
