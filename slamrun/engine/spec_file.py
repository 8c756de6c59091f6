"""A spec file read and checked: its YAML (bounded), its schema (spec.py: pure, nothing on this machine looked at),
then what it asks of this machine: methods' local builds and programs, a GPU, podman's GPU devices, the dataset
folders, the results and cache folders (whose they are). Every problem is listed at once, each with its line."""

from __future__ import annotations

import os
import re
from pathlib import Path

import yaml
from pydantic import ValidationError

import slamrun.methods
from slamrun.backends.monitor import host_gpus
from slamrun.core.inputs import expanded_size, read_text_bounded
from slamrun.core.suggest import did_you_mean
from slamrun.datasets.generated import target_problem
from slamrun.datasets.layouts import get as get_layout
from slamrun.datasets.layouts import holds_sequence
from slamrun.engine.folders import (
    CACHE,
    RESULTS,
    cache_overlap_problem,
    output_folder_problem,
)
from slamrun.engine.ledger import campaign_owner_problem
from slamrun.engine.spec import (
    CampaignSpec,
    _name_problems,
    raw_methods,
    schema_problems,
)
from slamrun.errors import SlamRunError, SpecError

YAML_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)  # libyaml's, where PyYAML has it: 5x faster, as safe
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
        node = yaml.compose(text, Loader=YAML_LOADER)
        if node is not None and (n := expanded_size(node)) > MAX_SPEC_VALUES:
            raise SpecError(
                str(path),
                [f"its YAML aliases expand to {n:,} values (at most {MAX_SPEC_VALUES:,}): an alias bomb? Write it out"],
            )
        raw = yaml.load(text, Loader=YAML_LOADER)  # noqa: S506 - a safe loader
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
    """The spec, or SpecError listing every problem: the schema's (spec.schema_problems), then this machine's.
    `check_gpu`: a method that needs a GPU is a problem on a host that has none, where this host runs the runs (not
    when a cluster's or a remote scheduler's workers do)."""
    spec, problems = schema_problems(raw)
    problems += method_problems(raw, GpuHere(check_gpu and runs_on_this_host(raw)))
    if spec is not None:
        spec = _resolve(spec, base_dir, results)
        if check_files and runs_on_this_host(raw):  # this machine runs it (not only reading or planning it)
            problems += cpu_fit(spec)[0]
        if check_files and not _name_problems(raw):
            problems += _file_problems(spec, "--results" if results is not None else "results")
        if check_files:
            problems += _published_problems(spec)
    if problems:
        raise SpecError(source, problems)
    assert spec is not None
    return spec


def method_problems(raw: dict, gpu_here: GpuHere) -> list[str]:
    """Why a method of the spec (its name and parameters valid) cannot run here with the spec's backend: a missing
    local build or program, an environment no process can start with, a GPU this host lacks."""
    problems = []
    backend = raw.get("backend", "local")
    for i, m in enumerate(raw_methods(raw)):
        if not isinstance(m, dict) or not isinstance(m.get("name"), str) or m["name"] not in slamrun.methods.REGISTRY:
            continue
        cls = slamrun.methods.REGISTRY[m["name"]]
        try:
            method = cls(cls.Params.model_validate(m.get("params") or {}))
        except ValidationError:
            continue  # named by the schema's step
        found = method.problems(backend) + method.launch_problems() + method.executable_problems(backend)
        if method.needs_gpu and gpu_here.missing():
            found.append(f"{m['name']} needs a GPU; this host has none (neither NVML nor nvidia-smi answers)")
        elif method.needs_gpu and gpu_here.check and backend == "podman":
            from slamrun.backends.podman import gpu_problem

            found += filter(None, [gpu_problem(m["name"])])
        problems += [f"methods[{i}]: {p}" for p in found]
    return problems


def cpu_fit(spec: CampaignSpec, cpus: int | None = None) -> tuple[list[str], list[str]]:
    """(problems, warnings): each method's busy threads (its declaration, with its parameters) against the CPUs a lane
    of this campaign gets here (`cpus`: those this process may use). More threads than CPUs make its threads wait
    for one, so its FPS and CPU figures are taken under contention: refused under `measurement: exclusive` (taken
    for timing), a warning otherwise. A method that gives no thread count (busy_threads() raised, or returned no int
    >= 1 nor None) is a problem, named in one line."""
    cpus = cpus or len(os.sched_getaffinity(0))
    exclusive = spec.measurement == "exclusive"
    lanes = 1 if exclusive else spec.lanes
    per_lane = cpus if exclusive else min(cpus, spec.cpus_per_lane or max(1, cpus // lanes))
    problems, warnings = lane_fit(spec, cpus)
    for i, m in enumerate(spec.methods):
        threads, why = _busy_threads(m)
        if why is not None:
            problems.append(f"methods[{i}]: {why}")
        if threads is None or threads <= per_lane:
            continue
        if exclusive:
            problems.append(
                f"methods[{i}]: {m.run_label} keeps {threads} threads busy, and measurement: exclusive gives it the "
                f"{cpus} CPU(s) this process may use: its FPS and CPU figures would be taken with threads waiting for "
                f"a CPU; measure it where {threads} CPUs are free, or with measurement: parallel"
            )
        else:
            fit = max(1, cpus // threads)
            warnings.append(
                f"{m.run_label} keeps {threads} threads busy, and each of the {lanes} lane(s) gets {per_lane} of the "
                f"{cpus} CPU(s) this process may use: its threads will wait for a CPU (cpu_wait_pct in results.csv "
                f"says how long){f'; lanes: {fit} gives each of its runs {threads}' if fit * threads <= cpus else ''}"
            )
    return problems, warnings


def lane_fit(spec: CampaignSpec, cpus: int) -> tuple[list[str], list[str]]:
    """(problems, warnings) of the lanes against the `cpus` this process may use: a lane of more CPUs than there are
    (refused), lanes that share CPUs (their runs share them: warned), exclusive measurement with more lanes than
    CPUs (refused: it runs one run at a time)."""
    problems, warnings = [], []
    if spec.cpus_per_lane is not None and spec.cpus_per_lane > cpus:
        problems.append(
            f"cpus_per_lane {spec.cpus_per_lane}: this process may use {cpus} CPU(s); give at most {cpus} (or none: "
            "the CPUs split between the lanes)"
        )
    if spec.measurement == "exclusive":
        if spec.lanes > cpus:
            problems.append(
                f"measurement: exclusive runs one run at a time on every CPU; lanes: {spec.lanes} asks for more runs "
                f"at once than this process's {cpus} CPU(s): set lanes: 1"
            )
        return problems, warnings
    per = min(cpus, spec.cpus_per_lane or max(1, cpus // spec.lanes))
    if spec.lanes * per > cpus:
        crowd = f"; {spec.lanes} lanes on {cpus} CPU(s): about {spec.lanes / cpus:.0f} runs at a time on each" * (
            spec.lanes > cpus
        )
        warnings.append(
            f"lanes share CPUs: {spec.lanes} lanes of {per} CPU(s) need {spec.lanes * per}, this process may use "
            f"{cpus}{crowd}: runs on the same CPUs wait for each other (their FPS and CPU figures taken under "
            f"contention); lanes: {max(1, cpus // per)} keeps them apart"
        )
    return problems, warnings


def _busy_threads(m) -> tuple[int | None, str | None]:
    """(the threads method `m` of a spec keeps busy with its parameters, None), or (None, why it gives no thread
    count, in one line naming it). (None, None) when the method cannot be made here: the schema's step names its
    parameters; a plug-in's own error in __init__ is its runs'."""
    from slamrun.methods.base import busy_threads_of

    cls = slamrun.methods.REGISTRY.get(m.name)
    try:
        method = cls(m.params) if cls is not None else None
    except Exception:  # noqa: BLE001 - see above
        method = None
    return busy_threads_of(method) if method is not None else (None, None)


def cpu_warnings(spec: CampaignSpec) -> list[str]:
    """cpu_fit's warnings where the runs execute on this machine (a cluster's workers have their own CPUs)."""
    here = spec.distributed is None or spec.distributed.address == "local"
    return cpu_fit(spec)[1] if here else []


def runs_on_this_host(raw: dict) -> bool:
    """Whether the spec's runs execute on this host: no `distributed`, or Dask workers on this machine."""
    d = raw.get("distributed")
    return not isinstance(d, dict) or d.get("address") == "local"


class GpuHere:
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


def _published_problems(spec: CampaignSpec) -> list[str]:
    """Each `published:` file that cannot be read as published figures, said before anything runs."""
    from slamrun.results.published import read_table

    problems = []
    for i, path in enumerate(spec.published):
        try:
            read_table(path)
        except SlamRunError as exc:
            problems.append(f"published[{i}]: {exc}")
    return problems


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
    published = [res(f) for f in spec.published]
    return spec.model_copy(update={"results": results, "cache": cache, "datasets": datasets, "published": published})


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
