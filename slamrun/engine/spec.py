"""The campaign spec: typed, self-documenting, validated all at once.

Relative paths in a spec file are resolved against the folder that holds the spec.
"""

from __future__ import annotations

import re
import typing
from enum import StrEnum
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

import slamrun.methods
from slamrun.backends.distributed import DistributedSpec, walltime_seconds  # noqa: F401 - the spec's part
from slamrun.core.suggest import did_you_mean
from slamrun.datasets.layouts import get as get_layout
from slamrun.datasets.view import Direction
from slamrun.engine.folders import (
    path_part_problem,
)
from slamrun.errors import DatasetError
from slamrun.results.catalogue import METRIC_NAMES
from slamrun.results.vocabulary import CONTENTION_PCT


class Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class SceneKind(StrEnum):
    indoor = "indoor"
    outdoor = "outdoor"


Motion = Literal["default", "plain", "hard"]  # datasets/synth.py MOTIONS (tested equal)


class SynthSpec(Strict):
    """Generate the dataset's sequences on first use (cached in its folder)."""

    frames: int = Field(300, ge=30, description="Frames per sequence.")
    seed: int = Field(0, description="Seed of the first sequence; the i-th sequence uses seed + i.")
    size: str = Field("640x480", pattern=r"^\d+x\d+$", description="Image size WIDTHxHEIGHT.")
    scene: SceneKind = Field(SceneKind.indoor, description="Room scale (indoor) or courtyard scale (outdoor).")
    motion: Motion = Field(
        "default",
        description="The camera paths' envelope: default, each seed's loop within the plain loop's speed, rotation "
        "rate and start parallax; plain, the plain loop for every seed; hard, faster and with less start parallax "
        "on purpose (README, Synthetic sequences).",
    )

    @property
    def size_wh(self) -> tuple[int, int]:
        w, h = self.size.split("x")
        return int(w), int(h)


class RpeSpec(Strict):
    """How far apart RPE's pose pairs are (see README, Metrics)."""

    delta: float = Field(gt=0, description="The interval, in `unit`.")
    unit: Literal["frames", "s", "m", "evo-f", "evo-m"] = Field(
        description="frames: the sequence's frames (pairs exactly delta frames apart); s: seconds (TUM RGB-D's "
        "per-second drift); m: metres along the ground truth; evo-f / evo-m: evo_rpe's --delta_unit f / m (steps of "
        "the estimate's own poses: an estimate written every 5th frame gets five times the interval)."
    )

    @model_validator(mode="after")
    def _valid(self):
        from slamrun.core.metrics import RpeInterval
        from slamrun.errors import MetricError

        try:
            RpeInterval(self.delta, self.unit)
        except MetricError as exc:
            raise ValueError(str(exc)) from None
        return self


PERTURBATION_KINDS = Literal[
    "gaussian_noise",
    "motion_blur",
    "exposure",
    "frame_drop",
    "resolution",
    "jpeg",
    "shot_noise",
    "impulse_noise",
    "defocus_blur",
    "glass_blur",
    "zoom_blur",
    "snow",
    "frost",
    "fog",
    "brightness",
    "contrast",
    "elastic_transform",
    "pixelate",
    "jpeg_compression",
]  # slamrun.datasets.perturb.KINDS and ImageNet-C's fifteen by their names (with `severity`; checked there)


class PerturbationSpec(Strict):
    """One kind of perturbation and its levels, e.g. {kind: gaussian_noise, sigma: [2, 5, 10]}: each level is a
    view of every sequence, beside the baseline (the ordinary view). README, Robustness."""

    kind: PERTURBATION_KINDS = Field(description="What is made worse (README, Robustness: each kind).")
    sigma: list[float] | None = Field(None, description="gaussian_noise: standard deviation, grey levels of 255.")
    length_px: list[int] | None = Field(None, description="motion_blur: the blur's length in pixels.")
    gain: list[float] | None = Field(None, description="exposure: intensities times gain (saturated).")
    every: list[int] | None = Field(None, description="frame_drop: every N-th frame is absent (2: half the rate).")
    scale: list[float] | None = Field(None, description="resolution: frames and camera scaled by this (< 1).")
    quality: list[int] | None = Field(None, description="jpeg: JPEG quality (1-95).")
    severity: list[int] | None = Field(
        None, description="ImageNet-C's corruptions (fog, snow, ..., gaussian_noise, motion_blur): severity 1-5."
    )
    draws: Literal["per_frame", "fixed"] = Field(
        "per_frame",
        description="The random parts (noise, a blur's angle, ImageNet-C's haze, flakes, frost): drawn per frame, or "
        "fixed (the first frame's on every frame: a fog that stays). README, Robustness.",
    )
    schedule: str = Field(
        "all",
        description="Which frames: all; burst:N/M (the last N of every M frames of the sequence); ramp (from none "
        "at the first frame to the level at the last). Not for resolution or frame_drop. README, Robustness.",
    )

    @field_validator("sigma", "length_px", "gain", "every", "scale", "quality", "severity", mode="before")
    @classmethod
    def _one_level_is_a_list(cls, v: Any) -> Any:
        if v is None:
            return v
        levels = [v] if not isinstance(v, list) else v
        if not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in levels):
            raise ValueError(f"a level is a number, e.g. [2, 5]; got {str(v)[:80]}")
        return levels

    @model_validator(mode="after")
    def _its_own_levels(self):
        from slamrun.datasets.perturb import IMAGENET_C, IMAGENET_C_MODELS, KINDS, schedule_problem

        if self.severity is None and self.kind not in KINDS:
            raise ValueError(
                f"{self.kind} is ImageNet-C's: give its severities, e.g. {{kind: {self.kind}, severity: [1, 3, 5]}}"
            )
        if self.severity is not None and self.kind not in IMAGENET_C_MODELS:
            raise ValueError(
                f"{self.kind} takes `{KINDS[self.kind].parameter}`, not severity (ImageNet-C's kinds: "
                f"{', '.join(IMAGENET_C_MODELS)})"
            )
        kind = KINDS[self.perturbation_kind]
        given = [f for f in LEVEL_FIELDS if getattr(self, f) is not None]
        others = [f for f in given if f != kind.parameter]
        if others:
            raise ValueError(f"{self.kind} takes `{kind.parameter}`, not {', '.join(others)}")
        levels = getattr(self, kind.parameter)
        if not levels:
            raise ValueError(f"{self.kind}: give its levels, e.g. {{kind: {self.kind}, {kind.parameter}: [...]}}")
        for level in levels:
            if (why := kind.valid(float(level))) is not None:
                raise ValueError(f"{self.kind}: {kind.parameter} {level}: {why}")
        if len(set(levels)) != len(levels):
            raise ValueError(f"{self.kind}: the levels of {kind.parameter} repeat")
        if (why := schedule_problem(self.kind, self.schedule)) is not None:
            raise ValueError(why)
        from slamrun.datasets.perturb import RANDOM

        if self.draws == "fixed" and self.perturbation_kind not in RANDOM:
            raise ValueError(f"{self.kind} has no random part: `draws: fixed` changes nothing (leave it out)")
        if self.perturbation_kind == IMAGENET_C + "frost":
            from slamrun.datasets.corruptions import frost_pictures

            if frost_pictures() is None:
                raise ValueError(
                    "frost blends in the frost pictures of the imagecorruptions package, which is not installed: "
                    "pip install --no-deps imagecorruptions==1.1.2 (its pictures are read, its code is not run)"
                )
        return self

    @property
    def perturbation_kind(self) -> str:
        """The kind as slamrun.datasets.perturb.KINDS names it: ImageNet-C's prefixed (imagenet_c.fog)."""
        from slamrun.datasets.perturb import IMAGENET_C

        return IMAGENET_C + self.kind if self.severity is not None else self.kind

    @property
    def levels(self) -> list[float]:
        from slamrun.datasets.perturb import KINDS

        return [float(v) for v in getattr(self, KINDS[self.perturbation_kind].parameter)]


LEVEL_FIELDS = ("sigma", "length_px", "gain", "every", "scale", "quality", "severity")


class DatasetSpec(Strict):
    name: str = Field(description="Dataset name, e.g. tum-mono.")
    path: Path = Field(description="Folder holding one folder per sequence.")
    sequences: list[str] = Field(
        min_length=1, description="Sequence folder names, e.g. [sequence_01, sequence_02], or one name."
    )

    @field_validator("sequences", mode="before")
    @classmethod
    def _one_name_is_a_list(cls, v: Any) -> Any:
        return [v] if isinstance(v, str) else v

    layout: str = Field(
        "tum-mono",
        description="The sequences' layout: tum-mono, euroc (ASL), kitti (sequences/NN), tum-rgbd, tum-vi, icl-nuim, "
        "tartanair, or a plug-in's (slamrun list-datasets); each sequence folder must be of it (recognised from its "
        "files), and synthetic sequences are written in it.",
    )

    @field_validator("layout")
    @classmethod
    def _known_layout(cls, v: str) -> str:
        try:
            get_layout(v)
        except DatasetError as exc:
            raise ValueError(str(exc)) from None
        return v

    synthetic: SynthSpec | None = Field(None, description="Generate missing sequences with `slamrun synth`.")
    metrics: list[Literal[METRIC_NAMES]] | None = Field(
        None,
        min_length=1,
        description="Metrics of each run against the ground truth: TUM-Mono's six, ATE, RPE (at `rpe:`), "
        "KITTI's segment errors. Default by layout: tum-mono for TUM-Mono; ate and rpe (and kitti for KITTI) for the "
        "others.",
    )

    @model_validator(mode="after")
    def _default_metrics(self):
        if self.metrics is None:
            from slamrun.datasets.layouts import DEFAULT_METRICS

            self.metrics = list(DEFAULT_METRICS[self.layout])
        if self.rpe is None:
            from slamrun.datasets.layouts import DEFAULT_RPE

            default = DEFAULT_RPE[self.layout]
            self.rpe = RpeSpec(delta=default.delta, unit=default.unit)
        return self

    min_coverage: float | None = Field(
        None,
        gt=0,
        le=1,
        description="A run that gives poses for fewer than this share of the sequence's frames (e.g. 0.75, as some "
        "groups publish) is a tracking failure (lost), its figures kept out of the statistics; default: no threshold "
        "(coverage is shown beside every figure).",
    )

    coverage_mark: float = Field(
        0.5,
        gt=0,
        le=1,
        description="Runs with poses for fewer than this share of the frames their method was given are marked low "
        "coverage in results.csv and in every view that shows their method (never ranked or set in bold without the "
        "mark); 0.5 by default.",
    )
    max_ate_rel: float | None = Field(
        None,
        gt=0,
        description="A run whose ATE RMSE exceeds this share of the ground truth's spread (its RMS distance from its "
        "centroid; 1 = no better than collapsing the estimate to one point) is a tracking failure, `diverged`; "
        "default: none (runs over 0.5 are flagged diverged in results.csv and every view either way). Needs `ate` "
        "among the metrics.",
    )

    rpe: RpeSpec | None = Field(
        None,
        description="RPE's interval, e.g. {delta: 1, unit: s}. Default by layout: one second of the sequence "
        "(slamrun list-datasets).",
    )

    @model_validator(mode="after")
    def _divergence_needs_ate(self):
        if self.max_ate_rel is not None and self.metrics is not None and "ate" not in self.metrics:
            raise ValueError(f"max_ate_rel judges a run by its ATE: add ate to metrics (now {', '.join(self.metrics)})")
        return self

    @property
    def evaluation(self):
        """How this dataset's runs are evaluated (engine.run_evaluation.EvalSettings)."""
        from slamrun.engine.run_evaluation import EvalSettings

        return EvalSettings(
            tuple(self.metrics or ()),
            self.alignment,
            self.rpe_interval,
            self.min_coverage,
            self.max_ate_rel,
            self.coverage_mark,
        )

    @property
    def rpe_interval(self):
        """`rpe` as the metric takes it."""
        from slamrun.core.metrics import RpeInterval

        assert self.rpe is not None
        return RpeInterval(self.rpe.delta, self.rpe.unit)

    alignment: str = Field(
        "sim3", description="Alignment before ATE, RPE and KITTI's metric: sim3 (monocular), se3, first:N, ..."
    )
    perturbations: list[PerturbationSpec] | None = Field(
        None,
        description="This dataset's perturbations (replacing the campaign's; [] for none): README, Robustness.",
    )

    @field_validator("alignment")
    @classmethod
    def _known_alignment(cls, v: str) -> str:
        from slamrun.core.metrics import Alignment
        from slamrun.errors import MetricError

        try:
            Alignment.parse(v)
        except MetricError as exc:
            raise ValueError(str(exc)) from None
        return v


class MethodSpec(Strict):
    name: str = Field(description="Registry name (see `slamrun list-methods`).")
    label: str | None = Field(None, description="Name in results (default: name); unique per spec.")
    params: dict[str, Any] = Field(default_factory=dict, description="Method parameters (checked by the method).")
    trials: int | None = Field(None, ge=1, description="Trials for this method (default: the campaign's).")
    directions: list[Direction] | None = Field(None, description="Directions for this method (default: campaign).")
    timeout_s: float | None = Field(None, gt=0, description="Per-run timeout for this method (default: campaign).")

    @property
    def run_label(self) -> str:
        return self.label or self.name


JOB_START_S = 60  # a worker job's own start-up, before it can take a run
# A spec's bounds, checked from its counts before any run is planned: a ledger row, a run folder and a process per
# run (200,000 runs at the runner's 60 runs/s of a no-op method are an hour of its own time); a view is a copy of a
# sequence's frames on disk
MAX_RUNS = 200_000
MAX_VIEWS = 10_000


class RecordedMethod(BaseModel):
    """A method entry of a recorded spec: its name, label and parameters as given (defaults not filled in)."""

    model_config = ConfigDict(extra="ignore")
    name: str
    label: str | None = None
    params: dict | None = None  # as given (None: none given)

    @property
    def run_label(self) -> str:
        return self.label or self.name


class RecordedSpec(BaseModel):
    """The spec as run (the ledger's record, else spec.resolved.yaml), read back for what the report, the live page
    and the session say of it: the campaign's settings they read, typed as CampaignSpec types them. Any other key is
    ignored and a missing one takes CampaignSpec's default, so a spec recorded by another version, or naming a
    plug-in that is not installed here, is still read."""

    model_config = ConfigDict(extra="ignore")
    name: str | None = None
    backend: str = "local"
    distributed: dict | None = None
    measurement: Literal["parallel", "exclusive"] = "parallel"
    lanes: int = 1
    cpus_per_lane: int | None = None
    contention_pct: float | None = None
    published: list[str] = []
    methods: list[RecordedMethod] = []

    @classmethod
    def read(cls, recorded: object) -> RecordedSpec | None:
        """`recorded` (a dict) as a RecordedSpec; None where nothing (or no mapping) was recorded or it does not
        fit the spec's types."""
        if not isinstance(recorded, dict):
            return None
        try:
            return cls.model_validate(recorded)
        except ValidationError:
            return None


class CampaignSpec(Strict):
    name: str = Field(pattern=r"^[A-Za-z0-9_.-]+$", description="Campaign name.")
    results: Path | None = Field(None, description="Results directory (default: results/<name>).")
    cache: Path | None = Field(None, description="Prepared-view cache (default: .cache/views beside results).")
    published: list[Path] = Field(
        [],
        description="CSV files of published figures to print beside this campaign's medians (README, Published "
        "figures); the built-in ones (DPVO's, DPV-SLAM's logs) are always read.",
    )
    datasets: list[DatasetSpec] = Field(min_length=1)
    methods: list[MethodSpec] = Field(min_length=1)
    directions: list[Direction] = Field(default_factory=lambda: [Direction.forward, Direction.backward])
    trials: int = Field(10, ge=1, description="Runs per (method, sequence, direction).")
    timeout_s: float = Field(1800.0, gt=0, description="Wall-clock limit of one run.")
    lanes: int = Field(1, ge=1, description="Runs in parallel, each pinned to its own CPU set.")
    cpus_per_lane: int | None = Field(None, ge=1, description="CPUs per lane (default: all CPUs split evenly).")
    memory_limit_mb: int | None = Field(None, ge=64, description="Memory limit per run (containers).")
    backend: Literal["local", "docker", "podman"] = Field(
        "local", description="Where runs execute: processes, Docker containers, or podman containers (no daemon)."
    )
    distributed: DistributedSpec | None = Field(
        None, description="Hand the runs to a distributed engine's workers (each runs them with `backend`)."
    )
    measurement: Literal["parallel", "exclusive"] = Field(
        "parallel", description="exclusive: one run at a time, nothing else (for timing)."
    )
    retries: int = Field(2, ge=0, description="Retries of infrastructure failures (never of method failures).")
    contention_pct: float | None = Field(
        None,
        ge=5,  # a run that loses tracking by itself waits 0.7-4.1 % (README): under 5 % every loss would be contended
        description="A run lost or never initialised while its threads waited for a CPU longer than this share of "
        f"its wall time (cpu_wait_pct) is `contended`: retried, and counted apart as infrastructure failures are, "
        f"never in the method's rate ({CONTENTION_PCT:g} measured to separate them on a shared machine; README). "
        "Default null: every loss is the method's.",
    )
    perturbations: list[PerturbationSpec] = Field(
        default_factory=list,
        description="Robustness: each sequence also played with its frames made worse, e.g. [{kind: gaussian_noise, "
        "sigma: [2, 5]}, {kind: frame_drop, every: [2]}]; every level a view of its own beside the baseline "
        "(README, Robustness). A dataset's own `perturbations` replace these.",
    )
    seed: int = Field(
        0,
        ge=0,
        description="The campaign's seed: each trial of a method that takes a seed (colmap, glomap, reference_vo, "
        "DPVO, DROID-SLAM) gets its own, derived from this and the trial, unless its params fix one.",
    )
    perturbation_seed: int = Field(
        0, ge=0, description="Seed of the perturbations' random parts (noise, blur angles): the same views anywhere."
    )
    retry_backoff_s: float = Field(5.0, ge=0, description="First retry delay; doubles each retry.")
    evaluate: bool = Field(True, description="Evaluate each finished run against the ground truth.")
    stop_grace_s: float = Field(30.0, ge=0, description="On SIGINT/SIGTERM, time in-flight runs get to finish.")
    log_cap_mb: float = Field(20.0, gt=0, description="Size cap of one run's log.txt.")
    max_output_mb: float = Field(
        4096.0,
        gt=0,
        description="Largest output one run may write (its work folder); past it, or when it fills the disk, the "
        "run is stopped, charged (output_limit) and its output removed.",
    )
    report: bool = Field(True, description="Write the report when the campaign ends.")
    frame_format: Literal["png", "pgm"] = Field(
        "png", description="Rectified frames on disk: png (compact) or pgm (fastest, ~4x the disk)."
    )

    @field_validator("directions")
    @classmethod
    def _unique_directions(cls, v: list[Direction]) -> list[Direction]:
        if len(set(v)) != len(v):
            raise ValueError("directions repeat")
        return v

    @model_validator(mode="after")
    def _within_bounds(self) -> CampaignSpec:
        levels = {
            id(ds): sum(len(p.levels) for p in (self.perturbations if ds.perturbations is None else ds.perturbations))
            for ds in self.datasets
        }
        played = sum(len(ds.sequences) * (1 + levels[id(ds)]) for ds in self.datasets)
        runs = sum((m.trials or self.trials) * len(m.directions or self.directions) * played for m in self.methods)
        directions = {d for m in self.methods for d in (m.directions or self.directions)}
        views = played * len(directions)
        if runs > MAX_RUNS:
            raise ValueError(
                f"the spec plans {runs:,} runs; slamrun takes at most {MAX_RUNS:,} in one spec (a ledger row, a run "
                "folder and a process each): split it into several specs, or give fewer levels, trials or sequences"
            )
        if views > MAX_VIEWS:
            raise ValueError(
                f"the spec needs {views:,} views (each a copy of a sequence's frames on disk); slamrun prepares at "
                f"most {MAX_VIEWS:,} for one spec: give fewer levels or sequences"
            )
        return self

    @model_validator(mode="after")
    def _exclusive_needs_one_machine(self) -> CampaignSpec:
        if self.distributed is not None and self.measurement == "exclusive":
            raise ValueError(
                "measurement 'exclusive' (timing) needs one machine with nothing else running; drop `distributed`"
            )
        d = self.distributed
        if d is not None and d.cluster is not None and d.walltime_s < self.timeout_s + self.stop_grace_s + JOB_START_S:
            raise ValueError(
                f"distributed.walltime {d.walltime} ({d.walltime_s} s) is shorter than one run may take: timeout_s "
                f"{self.timeout_s:g} + stop_grace_s {self.stop_grace_s:g} + {JOB_START_S} s for the worker to start; "
                "a job that ends mid-run costs that run. Raise walltime or lower timeout_s"
            )
        return self


def _loc(loc: tuple) -> str:
    out = ""
    for part in loc:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out or "<top>"


def _fields_at(model: type[BaseModel], loc: tuple) -> list[str]:
    """The field names of the model found at `loc` below `model` (list and dict items and optional fields passed
    through), or [] where `loc` leaves the models."""
    current: Any = model
    for part in loc:
        if isinstance(part, int):
            continue
        fields = getattr(current, "model_fields", {})
        if part not in fields:
            return []
        current = _model_in(fields[part].annotation)
        if current is None:
            return []
    return list(getattr(current, "model_fields", {}))


def _model_in(annotation: Any) -> type[BaseModel] | None:
    """The pydantic model an annotation holds (itself, or inside Optional/list/dict), or None."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    for arg in typing.get_args(annotation):
        if (found := _model_in(arg)) is not None:
            return found
    return None


def _message(err: dict, model: type[BaseModel], kind: str, raw: dict | None = None) -> str:
    """One pydantic error as the spec's reader needs it: an unknown `kind` (key or parameter) with the close one, a
    validator's own sentence without pydantic's "Value error, ", a choice with the close option, a number YAML read
    where a sequence name was meant."""
    loc, value = err["loc"], err.get("input")
    if err["type"] == "extra_forbidden":
        return f"unknown {kind}" + did_you_mean(str(loc[-1]), _fields_at(model, loc[:-1]))
    if err["type"] in ("value_error", "assertion_error") and "error" in (err.get("ctx") or {}):
        return str(err["ctx"]["error"])
    if err["type"] in ("literal_error", "enum") and isinstance(value, str):
        return err["msg"] + did_you_mean(value, re.findall(r"'([^']*)'", str(err["ctx"].get("expected", ""))))
    if err["type"] == "string_type" and loc[-2:-1] == ("sequences",) and _is_number(value):
        return _number_name(value, raw or {}, loc)
    return err["msg"]


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _number_name(value: int | float, raw: dict, loc: tuple) -> str:
    """A sequence name YAML read as a number (KITTI's 00 is the integer 0): what to write instead."""
    try:
        layout = raw["datasets"][loc[1]].get("layout")
    except (KeyError, IndexError, TypeError, AttributeError):
        layout = None
    name = f"{value:02d}" if layout == "kitti" and isinstance(value, int) and 0 <= value < 100 else str(value)
    return f'{value} is a number to YAML, not a folder name: quote it: "{name}"'


def schema_problems(raw: dict) -> tuple[CampaignSpec | None, list[str]]:
    """The spec as a schema alone (nothing on this machine is looked at: no folder, no GPU, no engine): the model, or
    None, and every problem of its keys, its methods' names and parameters, labels and sequence names."""
    problems: list[str] = []
    try:
        spec = CampaignSpec.model_validate(raw)
    except ValidationError as exc:
        for err in exc.errors():
            problems.append(f"{_loc(err['loc'])}: {_message(err, CampaignSpec, 'key', raw)}")
        spec = None
    # Method checks also run when other parts failed, so that every problem is listed at once.
    labels: dict[str, int] = {}
    for i, m in enumerate(raw_methods(raw)):
        if not isinstance(m, dict) or not isinstance(m.get("name"), str):
            continue
        try:
            cls = slamrun.methods.get(m["name"])
        except KeyError as exc:
            problems.append(f"methods[{i}].name: {exc.args[0]}")
            continue
        try:
            cls.Params.model_validate(m.get("params") or {})
        except ValidationError as exc:
            for err in exc.errors():
                problems.append(f"methods[{i}].params.{_loc(err['loc'])}: {_message(err, cls.Params, 'parameter')}")
        label = m.get("label") or m["name"]
        if label in labels:
            problems.append(f"methods[{i}].label: {label!r} used by methods[{labels[label]}] too; give a label")
        labels[label] = i
    problems += _name_problems(raw)
    if spec is not None:
        seen: dict[str, str] = {}
        for d, ds in enumerate(spec.datasets):
            for s, seq in enumerate(ds.sequences):
                if seq in seen:
                    problems.append(f"datasets[{d}].sequences[{s}]: {seq!r} also in dataset {seen[seq]!r}")
                seen[seq] = ds.name
    return spec, problems


def raw_methods(raw: dict) -> list:
    """The spec's `methods:` list as written (empty when it is not a list)."""
    return raw.get("methods") if isinstance(raw.get("methods"), list) else []


def _name_problems(raw: dict) -> list[str]:
    """Sequence names and method labels become path parts: none may hold a separator or be '..'; a label holds no
    ':' either (imported runs' labels are SOURCE:NAME, so the two never meet)."""
    problems = []
    datasets = raw.get("datasets") if isinstance(raw.get("datasets"), list) else []
    for d, ds in enumerate(datasets):
        sequences = ds.get("sequences") if isinstance(ds, dict) and isinstance(ds.get("sequences"), list) else []
        for s, seq in enumerate(sequences):
            if isinstance(seq, str) and (why := path_part_problem(seq)):
                problems.append(f"datasets[{d}].sequences[{s}]: the sequence name {why}")
    raw_methods = raw.get("methods") if isinstance(raw.get("methods"), list) else []
    for i, m in enumerate(raw_methods):
        label = (m.get("label") or m.get("name")) if isinstance(m, dict) else None
        if isinstance(label, str) and (why := path_part_problem(label)):
            problems.append(f"methods[{i}].label: the label (a folder name in the results) {why}")
        elif isinstance(label, str) and ":" in label:
            problems.append(
                f"methods[{i}].label: {label!r} holds ':', which marks runs imported with `slamrun import --as "
                "SOURCE:NAME` (their runs and this method's would be pooled in one row); choose a label without ':'"
            )
    return problems


def json_schema() -> dict:
    return CampaignSpec.model_json_schema()
