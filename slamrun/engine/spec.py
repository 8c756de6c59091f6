"""The campaign spec: typed, self-documenting, validated all at once.

Relative paths in a spec file are resolved against the folder that holds the spec.
"""

from __future__ import annotations

import os
import re
import typing
from enum import StrEnum
from pathlib import Path
from typing import Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

import slamrun.methods
from slamrun.backends.monitor import host_gpus
from slamrun.core.inputs import expanded_size, read_text_bounded
from slamrun.core.suggest import did_you_mean
from slamrun.datasets.generated import target_problem
from slamrun.datasets.layouts import get as get_layout
from slamrun.datasets.layouts import holds_sequence
from slamrun.datasets.view import Direction
from slamrun.engine.folders import (
    CACHE,
    RESULTS,
    cache_overlap_problem,
    campaign_owner_problem,
    output_folder_problem,
    path_part_problem,
)
from slamrun.errors import DatasetError, SlamRunError, SpecError
from slamrun.results.vocabulary import METRIC_NAMES


class Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class SceneKind(StrEnum):
    indoor = "indoor"
    outdoor = "outdoor"


class SynthSpec(Strict):
    """Generate the dataset's sequences on first use (cached in its folder)."""

    frames: int = Field(300, ge=30, description="Frames per sequence.")
    seed: int = Field(0, description="Seed of the first sequence; the i-th sequence uses seed + i.")
    size: str = Field("640x480", pattern=r"^\d+x\d+$", description="Image size WIDTHxHEIGHT.")
    scene: SceneKind = Field(SceneKind.indoor, description="Room scale (indoor) or courtyard scale (outdoor).")

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

    rpe: RpeSpec | None = Field(
        None,
        description="RPE's interval, e.g. {delta: 1, unit: s}. Default by layout: one second of the sequence "
        "(slamrun list-datasets).",
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


def walltime_seconds(text: str) -> int:
    """A walltime in Slurm's forms (M, M:S, H:M:S, D-H, D-H:M, D-H:M:S) in seconds; ValueError otherwise."""
    days, dash, clock = text.strip().rpartition("-")
    parts = clock.split(":")
    if (dash and not days.isdigit()) or not all(p.isdigit() for p in parts) or len(parts) > 3:
        raise ValueError(f"walltime {text!r} is not one of M, M:S, H:M:S, D-H, D-H:M, D-H:M:S")
    values = [int(p) for p in parts]
    if dash:  # D-H, D-H:M, D-H:M:S
        h, m, sec = (values + [0, 0])[:3]
    elif len(values) == 3:
        h, m, sec = values
    elif len(values) == 2:  # M:S
        h, m, sec = 0, *values
    else:  # M
        h, m, sec = 0, values[0], 0
    return int(days or 0) * 86400 + h * 3600 + m * 60 + sec


class DistributedSpec(Strict):
    """Runs executed by a distributed engine's workers instead of this machine's lanes: a Dask scheduler
    someone started (`address`), or Dask workers slamrun submits as batch jobs (`cluster`: Slurm, PBS, SGE,
    LSF through dask-jobqueue) and cancels when the campaign ends."""

    engine: Literal["dask"] = Field("dask", description="The engine: a Dask distributed cluster.")
    address: str | None = Field(
        None,
        description="Scheduler address (tcp://host:8786), or 'local' for `lanes` worker processes on this "
        "machine (loopback only; for trying it out). Results and view cache must be on a filesystem every "
        "worker sees at the same path.",
    )
    cluster: Literal["slurm", "pbs", "sge", "lsf"] | None = Field(
        None, description="Submit the workers as batch jobs of this scheduler (dask-jobqueue), instead of `address`."
    )
    queue: str | None = Field(None, description="Partition (Slurm) or queue the worker jobs go to.")
    account: str | None = Field(None, description="Account the jobs are charged to.")
    cores: int = Field(2, ge=1, description="CPU cores per worker job; a worker runs one run at a time.")
    memory: str = Field("8GB", pattern=r"^\d+(\.\d+)?\s*[KMGT]i?B$", description="Memory per worker job, e.g. 8GB.")
    walltime: str = Field("12:00:00", description="Walltime of one worker job; longer than timeout_s + stop_grace_s.")
    job_directives: list[str] = Field(
        default_factory=list, description="Extra batch directives, e.g. ['--gres=gpu:1'] (Slurm: #SBATCH lines)."
    )
    job_prologue: list[str] = Field(
        default_factory=list, description="Shell lines a job runs before its worker (module load, source a venv)."
    )
    python: str | None = Field(None, description="The workers' Python with slamrun installed (default: this one).")
    interface: str | None = Field(
        None, description="Network interface the scheduler and workers listen on (e.g. ib0; lo on one machine)."
    )
    min_workers: int = Field(1, ge=1, description="Worker jobs kept alive (a lost one is replaced).")
    max_workers: int | None = Field(None, ge=1, description="Most worker jobs at once (default: lanes).")
    worker_wait_s: float = Field(
        600.0, gt=0, description="How long to wait for the first worker job to start before giving up (with why)."
    )
    log_directory: Path | None = Field(None, description="The jobs' stdout/stderr (default: results/jobs).")

    @model_validator(mode="after")
    def _address_or_cluster(self) -> DistributedSpec:
        if (self.address is None) == (self.cluster is None):
            raise ValueError(
                "give either address (a running Dask scheduler, or 'local') or cluster (slurm, pbs, sge, lsf)"
            )
        if self.cluster is not None:
            walltime_seconds(self.walltime)
        if self.max_workers is not None and self.max_workers < self.min_workers:
            raise ValueError(f"max_workers {self.max_workers} is below min_workers {self.min_workers}")
        return self

    @property
    def walltime_s(self) -> int:
        return walltime_seconds(self.walltime)


class CampaignSpec(Strict):
    name: str = Field(pattern=r"^[A-Za-z0-9_.-]+$", description="Campaign name.")
    results: Path | None = Field(None, description="Results directory (default: results/<name>).")
    cache: Path | None = Field(None, description="Prepared-view cache (default: .cache/views beside results).")
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


MAX_SPEC_BYTES = 2**20  # a spec is a page of YAML
MAX_SPEC_VALUES = 100_000  # values in the document once its aliases are expanded


def load_spec(
    path: str | Path, check_files: bool = True, results: Path | None = None, check_gpu: bool = True
) -> CampaignSpec:
    """Read, validate and resolve a spec file; raises SpecError listing every problem, each with its line.
    `results` (the command line's --results) replaces the spec's results folder and is checked as it is;
    `check_gpu=False` accepts methods that need a GPU on a host without one (reading a campaign, not running it)."""
    path = Path(path)
    try:  # a regular file of at most a page: a FIFO or a device is refused without blocking on it
        text = read_text_bounded(path, MAX_SPEC_BYTES, "spec file")
    except SlamRunError as exc:
        raise SpecError(str(path), [str(exc).removeprefix(f"{path}: ")]) from None
    try:
        node = yaml.compose(text, Loader=yaml.SafeLoader)
        if node is not None and (n := expanded_size(node)) > MAX_SPEC_VALUES:
            raise SpecError(
                str(path),
                [f"its YAML aliases expand to {n:,} values (at most {MAX_SPEC_VALUES:,}): an alias bomb? Write it out"],
            )
        raw = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark else ""
        raise SpecError(str(path), [f"{where}not valid YAML ({getattr(exc, 'problem', exc)})"]) from None
    except RecursionError:
        raise SpecError(str(path), ["YAML nested too deeply to be a spec"]) from None
    if not isinstance(raw, dict):
        raise SpecError(str(path), ["expected a mapping at the top (name, datasets, methods, ...)"])
    try:
        return validate_spec(
            raw,
            base_dir=path.resolve().parent,
            source=str(path),
            check_files=check_files,
            results=results,
            check_gpu=check_gpu,
        )
    except SpecError as exc:
        raise SpecError(exc.source, _by_line([_with_line(p, node) for p in exc.problems])) from None


def _by_line(problems: list[str]) -> list[str]:
    """Problems in the order of their lines in the file (those without a line last, in their order)."""

    def line(problem: str) -> int:
        found = re.match(r"line (\d+): ", problem)
        return int(found.group(1)) if found else 1 << 30

    return sorted(problems, key=line)


def _with_line(problem: str, root: yaml.Node | None) -> str:
    """'methods[0].params.x: msg' -> 'line 12: methods[0].params.x: msg', the line of the deepest part of the
    location that the document has."""
    where, sep, msg = problem.partition(": ")
    if not sep or root is None or where.startswith("-"):  # a command-line flag's problem has no line
        return problem
    node, line = root, None
    for key, index in re.findall(r"([A-Za-z_][\w-]*)|\[(\d+)\]", where):
        if isinstance(node, yaml.MappingNode) and key:
            node = next((v for k, v in node.value if getattr(k, "value", None) == key), None)
        elif isinstance(node, yaml.SequenceNode) and index and int(index) < len(node.value):
            node = node.value[int(index)]
        else:
            node = None
        if node is None:
            break
        line = node.start_mark.line + 1
    return f"line {line}: {problem}" if line else problem


def validate_spec(
    raw: dict,
    base_dir: Path,
    source: str = "<spec>",
    check_files: bool = True,
    results: Path | None = None,
    check_gpu: bool = True,
) -> CampaignSpec:
    """The spec, or SpecError listing every problem. `check_gpu`: a method that needs a GPU is a problem on a host
    that has none, where this host runs the runs (not when a cluster's or a remote scheduler's workers do)."""
    problems: list[str] = []
    gpu_here = _GpuHere(check_gpu and runs_on_this_host(raw))
    try:
        spec = CampaignSpec.model_validate(raw)
    except ValidationError as exc:
        for err in exc.errors():
            problems.append(f"{_loc(err['loc'])}: {_message(err, CampaignSpec, 'key', raw)}")
        spec = None
    # Method checks also run when other parts failed, so that every problem is listed at once.
    raw_methods = raw.get("methods") if isinstance(raw.get("methods"), list) else []
    labels: dict[str, int] = {}
    for i, m in enumerate(raw_methods):
        if not isinstance(m, dict) or not isinstance(m.get("name"), str):
            continue
        try:
            cls = slamrun.methods.get(m["name"])
        except KeyError as exc:
            problems.append(f"methods[{i}].name: {exc.args[0]}")
            continue
        try:
            params = cls.Params.model_validate(m.get("params") or {})
        except ValidationError as exc:
            for err in exc.errors():
                problems.append(f"methods[{i}].params.{_loc(err['loc'])}: {_message(err, cls.Params, 'parameter')}")
        else:
            backend = raw.get("backend", "local")
            method = cls(params)
            found = method.problems(backend) + method.launch_problems() + method.executable_problems(backend)
            if method.needs_gpu and gpu_here.missing():
                found.append(f"{m['name']} needs a GPU; this host has none (neither NVML nor nvidia-smi answers)")
            elif method.needs_gpu and gpu_here.check and backend == "podman":
                from slamrun.backends.podman import gpu_problem

                found += filter(None, [gpu_problem(m["name"])])
            problems += [f"methods[{i}]: {p}" for p in found]
        label = m.get("label") or m["name"]
        if label in labels:
            problems.append(f"methods[{i}].label: {label!r} used by methods[{labels[label]}] too; give a label")
        labels[label] = i
    names = _name_problems(raw)
    problems += names
    if spec is not None:
        spec = _resolve(spec, base_dir, results)
        if check_files and not names:
            problems += _file_problems(spec, "--results" if results is not None else "results")
        seen: dict[str, str] = {}
        for d, ds in enumerate(spec.datasets):
            for s, seq in enumerate(ds.sequences):
                if seq in seen:
                    problems.append(f"datasets[{d}].sequences[{s}]: {seq!r} also in dataset {seen[seq]!r}")
                seen[seq] = ds.name
    if problems:
        raise SpecError(source, problems)
    assert spec is not None
    return spec


def runs_on_this_host(raw: dict) -> bool:
    """Whether the spec's runs execute on this host: no `distributed`, or Dask workers on this machine."""
    d = raw.get("distributed")
    return not isinstance(d, dict) or d.get("address") == "local"


class _GpuHere:
    """Whether this host lacks a GPU, asked once (NVML, then nvidia-smi) and only when a method needs one."""

    def __init__(self, check: bool):
        self.check = check
        self._gpus: list[str] | None = None

    def missing(self) -> bool:
        if not self.check:
            return False
        if self._gpus is None:
            self._gpus = host_gpus()
        return not self._gpus


def _resolve(spec: CampaignSpec, base: Path, results_flag: Path | None = None) -> CampaignSpec:
    """Absolute paths; `results_flag` (--results, relative to the working directory) replaces the results folder
    (the default cache stays beside the spec's own results)."""

    def res(p: Path) -> Path:
        p = Path(os.path.expanduser(str(p)))
        return p if p.is_absolute() else (base / p).resolve()

    results = res(spec.results) if spec.results else (Path.cwd() / "results" / spec.name).resolve()
    cache = res(spec.cache) if spec.cache else results.parent / ".cache" / "views"
    if results_flag is not None:
        results = Path(os.path.expanduser(str(results_flag))).resolve()
    datasets = [ds.model_copy(update={"path": res(ds.path)}) for ds in spec.datasets]
    return spec.model_copy(update={"results": results, "cache": cache, "datasets": datasets})


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


def output_problems(spec: CampaignSpec, results_source: str = "results") -> list[str]:
    """Why the campaign may not write where the resolved spec says (results, view cache), each with the key or flag
    that named the folder: the one guard of every door to where a campaign writes. Reads only."""
    problems = []
    if why := output_folder_problem(spec.results, RESULTS) or campaign_owner_problem(spec.results, spec.name):
        problems.append(f"{results_source}: {why}")
    datasets = [ds.path for ds in spec.datasets]
    if why := cache_overlap_problem(spec.cache, spec.results, datasets) or output_folder_problem(spec.cache, CACHE):
        problems.append(f"cache: {why}")
    return problems


def _file_problems(spec: CampaignSpec, results_source: str = "results") -> list[str]:
    problems = output_problems(spec, results_source)
    for d, ds in enumerate(spec.datasets):
        if ds.synthetic is not None:
            if get_layout(ds.layout).synth is None:
                problems.append(f"datasets[{d}].synthetic: layout {ds.layout} has no synthetic writer")
                continue
            if ds.path.exists() and not ds.path.is_dir():
                problems.append(f"datasets[{d}].path: {ds.path} exists and is not a folder")
                continue
            for s, seq in enumerate(ds.sequences):
                folder = ds.path / seq
                if not holds_sequence(folder) and (why := target_problem(folder)):
                    problems.append(f"datasets[{d}].sequences[{s}]: {why}")
                if (check := get_layout(ds.layout).synth_name_problem) is not None and (why := check(seq)):
                    problems.append(f"datasets[{d}].sequences[{s}]: {why}")
            continue
        if not ds.path.is_dir():
            problems.append(f"datasets[{d}].path: folder {ds.path} not found (download it: slamrun dataset download)")
            continue
        missing = [(s, seq) for s, seq in enumerate(ds.sequences) if not (ds.path / seq).is_dir()]
        present = _sequence_folders(ds.path) if missing else []
        for s, seq in missing:
            problems.append(
                f"datasets[{d}].sequences[{s}]: {ds.path / seq} not found{did_you_mean(seq, present)} "
                f"({_listing(ds.path, present)})"
            )
    return problems


LISTED = 8  # folder names a "not found" lists


def _sequence_folders(path: Path) -> list[str]:
    """The folders in a dataset folder (not hidden), sorted."""
    try:
        return sorted(p.name for p in path.iterdir() if p.is_dir() and not p.name.startswith("."))
    except OSError:
        return []


def _listing(path: Path, names: list[str]) -> str:
    if not names:
        return f"{path} holds no folder"
    more = f" and {len(names) - LISTED} more" if len(names) > LISTED else ""
    return f"{path} holds {', '.join(names[:LISTED])}{more}"


def json_schema() -> dict:
    return CampaignSpec.model_json_schema()
