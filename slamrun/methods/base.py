"""The method contract: a small class with configure, command and read_trajectory."""

from __future__ import annotations

import functools
import numbers
import os
import re
import shutil
import sys
from abc import ABC, abstractmethod
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from slamrun.core.trajectory import Trajectory, read_tum
from slamrun.datasets.view import PreparedView, Profile
from slamrun.errors import MethodFailure, TrajectoryFormatError, one_line
from slamrun.methods.declare import NativeMethod, Source, VerifyScope, Vocabulary, Weights

MAX_ARG_BYTES = 131072  # Linux's limit on one argument or environment string (MAX_ARG_STRLEN)


BUILT_IN = Path(__file__).resolve().parent  # slamrun/methods/: each folder with an __init__.py is a method


def image_tag(name: str) -> str:
    """The tag of a built-in method's image (built from its folder's image/Dockerfile)."""
    return f"slamrun/{name}:latest"


class NoParams(BaseModel):
    model_config = ConfigDict(extra="forbid")


def trial_seed_param(seeds: str, fixed: str) -> Any:
    """A method's `seed` parameter (its seed_param), None by default: each trial then gets its own seed
    (engine.plan.trial_seed). `seeds` says what it seeds, `fixed` what a value the spec fixes does."""
    return Field(
        None, description=f"{seeds}; default: one per trial, from the trial and the campaign's seed ({fixed})."
    )


class Method(ABC):
    """One SLAM/VO method. Subclasses set the class attributes and implement `command`.

    `configure` and `command` get paths as the method's process sees them (on the host for the local
    backend, /data and /work inside a container); `read_trajectory` gets host paths, since the runner
    reads the outputs.
    """

    name: ClassVar[str]
    image: ClassVar[str | None] = None  # Docker tag; None for a method that only runs natively
    profile: ClassVar[Profile] = Profile.native  # which prepared view it consumes
    needs_gpu: ClassVar[bool] = False  # a GPU is requested for the run
    gpu_capable: ClassVar[bool] = False  # can use a GPU when asked (params.gpu); runs on the CPU otherwise
    loop_closure_switch: ClassVar[str | None] = None  # how the image turns loop closure off, if it has one
    native: ClassVar[bool] = False  # runs as a local process without an image
    # the Python modules whose versions decide its results when it runs natively (recorded with each run)
    modules: ClassVar[tuple[str, ...]] = ()
    Params: ClassVar[type[BaseModel]] = NoParams
    output_file: ClassVar[str] = "trajectory.txt"
    # Log lines that tell why a run produced nothing usable (case-insensitive regular expressions).
    not_initialized_pattern: ClassVar[str | None] = None
    lost_pattern: ClassVar[str | None] = None
    # Log lines that say the machine lacks what the method needs (no GPU, too little GPU memory): the run is an
    # infrastructure failure (retried, never charged to the method)
    infra_pattern: ClassVar[str | None] = None
    # Its declaration for the toolchain (slamrun/images/), each read from the class that writes it (declare.declared):
    sources: ClassVar[tuple[Source, ...]] = ()  # the pinned archives its image (or native build) builds from
    vocabulary: ClassVar[Vocabulary | None] = None  # the vocabulary its image needs
    network: ClassVar[Weights | None] = None  # the trained network its image needs (weights file)
    verify_bound: ClassVar[float] = 0.05  # `slamrun verify`: settled e_align / scene extent it must stay under
    verify_scope: ClassVar[VerifyScope | None] = None  # `slamrun verify` runs less than its default (why, in it)
    verified: ClassVar[bool] = True  # `slamrun verify` checks its image (slamrun's own reference method: its tests)
    native_build: ClassVar[NativeMethod | None] = None  # how `slamrun native-build` makes it
    # Configurations its authors publish as methods of their own, by the name they publish (DPV-SLAM: DPVO with
    # loop_closure: true): a spec runs one as {name: <this>, label: <variant>, params: ...}; scripts/gpu-check.sh runs
    # each beside the default (slamrun list-methods --json)
    variants: ClassVar[dict[str, dict]] = {}
    # The parameter that seeds its randomness (None: it takes no seed). Unless the spec fixes it, each trial gets its
    # own seed, derived from the trial and the campaign's `seed` (engine.plan.trial_seed), recorded in run.json.
    seed_param: ClassVar[str | None] = None
    # Given the same input and seed, the same output bit for bit: with its seed fixed, its trials are copies (counted
    # once by the statistics; validate, plan and the dry run say so)
    deterministic: ClassVar[bool] = False
    # Threads it keeps busy at once (tracking, mapping, ...): a lane with fewer CPUs makes its threads wait for one;
    # None: it uses as many as its lane has (COLMAP's thread count follows the CPUs it is pinned to). An int >= 1 or
    # None (threads_problem): a plug-in declaring another value is not registered; its busy_threads() returning one
    # is its own failure (guarded)
    threads: ClassVar[int | None] = 1

    def __init_subclass__(cls, **kwargs) -> None:
        """A built-in method's folder names it: the class declared in slamrun/methods/<folder>/__init__.py takes the
        folder's name, and the tag of the image its image/Dockerfile builds, unless it declares its own; so a copy of
        a folder is a method of its own, whatever its class body says."""
        super().__init_subclass__(**kwargs)
        path = Path(getattr(sys.modules.get(cls.__module__), "__file__", None) or "/").resolve()
        if path.name != "__init__.py" or path.parent.parent != BUILT_IN:
            return
        if "name" not in vars(cls):
            cls.name = path.parent.name
        if "image" not in vars(cls) and (path.parent / "image" / "Dockerfile").is_file():
            cls.image = image_tag(cls.name)

    def __init__(self, params: BaseModel | dict | None = None):
        self.params = params if isinstance(params, BaseModel) else self.Params.model_validate(params or {})

    @classmethod
    def folder(cls) -> Path:
        """The folder of the module that declares this method (a built-in's: slamrun/methods/<name>/)."""
        return Path(sys.modules[cls.__module__].__file__).resolve().parent

    @classmethod
    def recipe(cls) -> Path:
        """Its image's Dockerfile: image/Dockerfile in its folder (it may not exist: a native-only method)."""
        return cls.folder() / "image" / "Dockerfile"

    def configure(self, view: PreparedView, workdir: Path) -> dict[str, str]:
        """The method's own config files: {path relative to the work directory: content}.

        Pure: the runner writes them, so the same call serves a local process and a container.
        """
        return {}

    def frames_given(self, n: int) -> np.ndarray | None:
        """The indices of a view's `n` frames (in the order the view plays them) this method takes with its parameters,
        e.g. every stride-th (`strided`); None: all of them. A run's coverage is of the frames it was given."""
        return None

    def busy_threads(self) -> int | None:
        """The threads this method keeps busy with its parameters (`threads`, unless a setting changes it)."""
        return self.threads

    def for_backend(self, backend: str) -> Method:
        """This method as run by a backend (`local` or `docker`); the interpreter may differ."""
        return self

    def environment(self) -> dict[str, str]:
        """Environment variables of the method's process (e.g. a loop-closure switch)."""
        return {}

    def problems(self, backend: str) -> list[str]:
        """Why this method cannot run on `backend` as configured ([] when it can); checked before any run."""
        if backend == "local" and not self.native:
            return [
                f"{self.name} has no native build here: give params.executable (a local build) or use backend: docker"
            ]
        return []

    def launch_problems(self) -> list[str]:
        """Why no process could ever be started with this method's environment (a spec error, never an
        infrastructure retry): Linux refuses an argument or variable of MAX_ARG_BYTES or more."""
        out = []
        for key, value in self.environment().items():
            size = len(key.encode()) + len(value.encode()) + 1
            if size >= MAX_ARG_BYTES:
                out.append(
                    f"environment variable {key}: {size} bytes; no process can be started with a variable of "
                    f"{MAX_ARG_BYTES // 1024} KiB or more (pass a file instead)"
                )
        return out

    def executable_problems(self, backend: str) -> list[str]:
        """Why the program of `params.executable` (a local build) cannot be started by the local backend ([] when
        it can, or when the method has no such parameter or runs in a container); checked before any run, so a
        missing program is a spec error, never an infrastructure retry at every start."""
        program = getattr(self.params, "executable", None)
        if backend != "local" or not isinstance(program, str):
            return []
        why = executable_problem(program)
        return [f"{self.name}: params.executable: {why}"] if why else []

    @abstractmethod
    def command(self, view: PreparedView, workdir: Path) -> list[str]:
        """The argv that runs the method (never a shell string)."""

    def read_trajectory(self, workdir: Path, view: PreparedView) -> Trajectory:
        """The method's output as a trajectory with ORIGINAL timestamps; MethodFailure when unusable."""
        return view.to_original(read_tum_output(workdir / self.output_file))

    def accepts_exit(self, exit_code: int, workdir: Path) -> bool:
        """Whether this exit code still means the output is complete (LDSO exits 139 after writing)."""
        return exit_code == 0

    def build_record(self) -> dict | None:
        """What its native build is, for run.json (source, patches, targets, what its network is), when it runs one
        on the local backend; None: nothing to say (an image's labels say it for a container)."""
        return None

    def infra_from_log(self, log_tail: str) -> str | None:
        """The log's line saying the machine lacks what the method needs (its infra_pattern), if there is one."""
        if self.infra_pattern and (m := re.search(f"(?:{self.infra_pattern}).*", log_tail, re.I | re.M)):
            return m.group(0).strip()
        return None

    def failure_from_log(self, log_tail: str) -> str | None:
        """`not_initialized` or `lost` when the log says so."""
        if self.not_initialized_pattern and re.search(self.not_initialized_pattern, log_tail, re.I | re.M):
            return "not_initialized"
        if self.lost_pattern and re.search(self.lost_pattern, log_tail, re.I | re.M):
            return "lost"
        return None


def strided(n: int, stride: int) -> np.ndarray:
    """Every `stride`-th of `n` frames from the first, and the last (as colmap's, glomap's and DPVO's processes take
    them)."""
    chosen = np.arange(0, n, max(1, int(stride)))
    return chosen if not n or chosen[-1] == n - 1 else np.append(chosen, n - 1)


def executable_problem(program: str) -> str | None:
    """Why `program` cannot be started as a run's argv[0] (a run's working folder is its own work folder), or None:
    a name is looked up on PATH; a path must be absolute, a file, and executable."""
    if not program:
        return "empty; give the program's full path"
    if "/" not in program:
        return None if shutil.which(program) else f"{program!r} is no program on PATH; give its full path"
    path = Path(program)
    if not path.is_absolute():
        return (
            f"{program!r} is a relative path, which a run would look up in its own work folder (it holds only the "
            "method's config files); give the full path"
        )
    if not path.exists():
        return f"{program} not found"
    if not path.is_file():
        return f"{program} is not a file"
    if not os.access(path, os.X_OK):
        return f"{program} is not executable (chmod +x it)"
    return None


def read_tum_output(path: Path) -> Trajectory:
    """A method's TUM output, with the method-failure kinds for a missing or empty file."""
    if not path.exists():
        raise MethodFailure("no_output", f"the method wrote no {path.name}")
    return require_poses(read_tum(path), path)


def require_poses(traj: Trajectory, path: Path) -> Trajectory:
    """The trajectory, unless it holds no pose: `no_output` when every row was NaN or infinite (the method
    wrote garbage), `not_initialized` when the file was empty."""
    if len(traj) == 0:
        if traj.report.n_nonfinite_dropped:
            raise MethodFailure("no_output", f"{path.name}: all {traj.report.n_rows} rows are NaN or infinite")
        raise MethodFailure("not_initialized", f"{path.name} holds no pose")
    return traj


GUARDED_CALLS = (
    "__init__",
    "frames_given",
    "configure",
    "command",
    "read_trajectory",
    "environment",
    "accepts_exit",
    "failure_from_log",
    "infra_from_log",
    "build_record",
    "for_backend",
    "problems",
    "launch_problems",
    "executable_problems",
    "busy_threads",
)


def guarded(cls: type[Method], who: str) -> type[Method]:
    """`cls` (someone else's method class) whose calls never raise anything but MethodFailure (and
    TrajectoryFormatError from read_trajectory): any other exception, sys.exit() included (not Ctrl-C), becomes
    MethodFailure('crashed') with one line naming `who`, the call and the exception; so does a value slamrun cannot
    use (RETURN_CHECKS: read_trajectory's trajectory, busy_threads' thread count). A plug-in's bug is then its own
    failure, recorded as a result, never an infrastructure fault retried at every start nor a stopped slamrun."""

    def wrap(attr: str):
        inner = getattr(cls, attr)

        @functools.wraps(inner)
        def call(self, *args, **kwargs):
            try:
                value = inner(self, *args, **kwargs)
            except (MethodFailure, TrajectoryFormatError, KeyboardInterrupt, GeneratorExit):
                raise
            except BaseException as exc:  # noqa: BLE001 - whatever a plug-in raises is its own failure
                raise MethodFailure("crashed", f"{who}: {cls.__name__}.{attr}() raised {one_line(exc)}") from None
            if (check := RETURN_CHECKS.get(attr)) and (why := check(value)):
                raise MethodFailure("crashed", f"{who}: {cls.__name__}.{attr}() returned {why}")
            return int(value) if attr == "busy_threads" and value is not None else value

        return call

    namespace = {attr: wrap(attr) for attr in GUARDED_CALLS}
    namespace.update(__module__=cls.__module__, __qualname__=cls.__qualname__, __doc__=cls.__doc__)
    return type(cls.__name__, (cls,), namespace)


def threads_problem(value) -> str | None:
    """What `value` is when it is no thread count (`threads`, busy_threads()): an int >= 1, or None (as many as its
    lane has CPUs); else None."""
    if value is None or (isinstance(value, numbers.Integral) and not isinstance(value, bool) and value >= 1):
        return None
    return f"{value!r}; expected an int >= 1, or None (as many threads as its lane has CPUs)"


def busy_threads_of(method: Method) -> tuple[int | None, str | None]:
    """(the threads `method` keeps busy with its parameters, None), or (None, why it gives no thread count, in one
    line: a plug-in's busy_threads() is guarded, so its error names it and its package; a built-in's names it)."""
    try:
        busy = method.busy_threads()
    except MethodFailure as exc:
        return None, str(exc)
    except Exception as exc:  # noqa: BLE001 - a built-in's bug, said in one line
        return None, f"{method.name}: busy_threads() raised {one_line(exc)}"
    if why := threads_problem(busy):
        return None, f"{method.name}: busy_threads() returned {why}"
    return busy, None


def not_a_trajectory(value) -> str | None:
    """What `value` is when it is not a usable Trajectory (a plug-in's read_trajectory returned it), else None."""
    if not isinstance(value, Trajectory):
        return f"{type(value).__name__}, not a Trajectory"
    shapes = [np.shape(value.timestamps), np.shape(value.positions), np.shape(value.quaternions)]
    n = shapes[0][0] if len(shapes[0]) == 1 else -1
    if shapes != [(n,), (n, 3), (n, 4)]:
        counts = [s[0] if s else 0 for s in shapes]
        return f"a Trajectory of {counts[0]} times, {counts[1]} positions and {counts[2]} rotations"
    for name in ("timestamps", "positions", "quaternions"):
        if not np.issubdtype(np.asarray(getattr(value, name)).dtype, np.number):
            return f"a Trajectory whose {name} are not numbers"
    return None


def not_a_line(value) -> str | None:
    """Why infra_from_log's value is no line of the log (None or a string expected)."""
    return None if value is None or isinstance(value, str) else f"{type(value).__name__} {value!r}: not a line of text"


def not_a_record(value) -> str | None:
    """Why build_record's value is no record for run.json (None or a dict expected)."""
    return None if value is None or isinstance(value, dict) else f"{type(value).__name__} {value!r}: not a dict"


# guarded: what a call returns
RETURN_CHECKS = {
    "read_trajectory": not_a_trajectory,
    "busy_threads": threads_problem,
    "infra_from_log": not_a_line,
    "build_record": not_a_record,
}


class PythonProcess:
    """Mixin for methods run as `python -m ...`: this interpreter locally, the image's python3 in a container."""

    python: str = sys.executable

    def for_backend(self, backend: str) -> Method:
        method = type(self)(self.params)
        method.python = sys.executable if backend == "local" else "python3"
        return method
