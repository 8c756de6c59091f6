"""What every backend takes and gives back."""

from __future__ import annotations

import os
import shutil
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

from slamrun.datasets.view import PreparedView

if TYPE_CHECKING:
    from slamrun.backends.monitor import ResourceSeries


@dataclass(frozen=True)
class ExecRequest:
    """One run's process, as the scheduler asks for it."""

    argv: list[str]
    workdir: Path  # host path of the run's work directory (read-write)
    view: PreparedView  # host path of the prepared view (read-only)
    log_path: Path
    resources_path: Path
    timeout_s: float
    cpus: tuple[int, ...] | None = None
    memory_mb: int | None = None
    log_cap_bytes: int = 20 * 2**20
    image: str | None = None
    needs_gpu: bool = False
    labels: dict[str, str] = field(default_factory=dict)
    env: dict[str, str] = field(default_factory=dict)
    token: str = ""  # marks every process of the run (RunPaths.token); a backend may make its own
    modules: tuple[str, ...] = ()  # the method's Python modules, whose versions a remote worker reports
    max_output_bytes: int | None = None  # the run's work folder may not grow past this (spec max_output_mb)


@dataclass(frozen=True)
class ExecResult:
    exit_code: int | None
    wall_s: float
    timed_out: bool = False
    oom: bool = False
    cancelled: bool = False
    log_truncated: bool = False
    resources: dict = field(default_factory=dict)
    output_exceeded: str | None = None  # why the run was stopped for its output (too large, or it filled the disk)
    machine: dict | None = None  # the host that ran it, where not this one (a Dask worker's)
    packages: dict | None = None  # there, the versions of the request's `modules`


class Backend(Protocol):
    """What the campaign asks of a backend. The last four are optional features: `Defaults` gives a backend
    that lacks them their neutral form."""

    name: str
    engine: str | None  # the engine runs go through beside the backend (e.g. "dask"), for run.json

    def check(self, images: dict[str, str | None] | None = None) -> None:
        """Raise InfraError before any run starts when the backend cannot work (daemon unreachable, images
        missing: `images` maps method names to their image tags)."""

    def process_paths(self, view: PreparedView, workdir: Path) -> tuple[PreparedView, Path]:
        """The view and work directory as the method's process sees them."""

    def execute(
        self, req: ExecRequest, cancel: threading.Event, on_start: Callable[[int, float], None] | None = None
    ) -> ExecResult:
        """Run to completion, timeout or cancel; always leaves no process behind."""

    def describe_image(self, tag: str) -> dict | None:
        """The image a run used (id, sources, vocabulary, weights), for run.json; None when the backend does not
        know it (no image runs here)."""

    def leftovers(self, campaign: str, results_id: str = "") -> list:
        """Runs of this campaign and results folder that a killed runner or a lost daemon left behind, for `collect`
        (containers)."""

    def collect(self, leftover, log_path: Path, log_cap_bytes: int, n_frames: int) -> ExecResult | None:
        """The result of a leftover that ended by itself; None while it runs or when it never started."""

    def close(self) -> None:
        """Release what the backend holds (a cluster client)."""


class Defaults:
    """The optional features' neutral forms, for backends that have no images, leftovers or resources."""

    engine: str | None = None

    def describe_image(self, tag: str) -> dict | None:
        return None

    def leftovers(self, campaign: str, results_id: str = "") -> list:
        return []

    def collect(self, leftover, log_path: Path, log_cap_bytes: int, n_frames: int) -> ExecResult | None:
        return None

    def close(self) -> None:
        pass


def supervise(
    wait_step: Callable[[float], bool],
    t0: float,
    timeout_s: float,
    cancel: threading.Event,
    output: OutputWatch | None = None,
) -> tuple[bool, bool, str | None]:
    """Wait for a run until it ends, its wall-clock timeout passes, `cancel` is set or its output grows past
    what it may write.

    `wait_step(remaining_s)` waits a short while and returns True once the process has ended.
    Returns (timed_out, cancelled, why the output stopped it or None).
    """
    while True:
        remaining = t0 + timeout_s - time.monotonic()
        if remaining <= 0:
            return True, False, None
        if cancel.is_set():
            return False, True, None
        if output is not None and (exceeded := output.check()):
            return False, False, exceeded
        if wait_step(remaining):  # ended: what it left counts too
            return False, False, output.check(force=True) if output is not None else None


def supervised_result(
    req: ExecRequest,
    series: ResourceSeries,
    exit_code: int | None,
    wall_s: float,
    stopped: tuple[bool, bool, str | None],
    log_truncated: bool,
    oom: bool = False,
) -> ExecResult:
    """The result of a run `supervise` waited for (`stopped`: what it returned), its resource samples written to
    req.resources_path and summed up; out of memory only where neither its timeout nor a cancel stopped it."""
    timed_out, cancelled, exceeded = stopped
    series.write_csv(req.resources_path)
    return ExecResult(
        exit_code=exit_code,
        wall_s=wall_s,
        timed_out=timed_out,
        cancelled=cancelled,
        oom=oom and not timed_out and not cancelled,
        log_truncated=log_truncated,
        resources=series.summary(wall_s, req.view.n_frames),
        output_exceeded=exceeded,
    )


def folder_bytes(root: Path) -> int:
    """Bytes of the regular files below `root` (links not followed)."""
    total = 0
    stack = [root]
    while stack:
        try:
            entries = list(os.scandir(stack.pop()))
        except OSError:
            continue
        for e in entries:
            try:
                if e.is_dir(follow_symlinks=False):
                    stack.append(Path(e.path))
                elif e.is_file(follow_symlinks=False):
                    total += e.stat(follow_symlinks=False).st_size
            except OSError:
                pass
    return total


def disk_reserve_bytes(path: Path) -> int:
    """The free space a run may not eat into: 10 % of its filesystem, at most 256 MiB. A run that holds at least
    that much output when the free space falls below it is the one filling the disk."""
    return min(256 * 2**20, shutil.disk_usage(path).total // 10)


class OutputWatch:
    """Watches a run's work folder: past `max_bytes`, or holding at least the disk reserve while the free
    space is below it, the run must stop (and is charged: output_limit). The free space is read often
    (one statfs), the folder's size once a second or when the space runs low."""

    def __init__(self, workdir: Path, max_bytes: int, size_every_s: float = 1.0):
        self.workdir = workdir
        self.max_bytes = max_bytes
        self.reserve = disk_reserve_bytes(workdir)
        self.size_every_s = size_every_s
        self._next_size = 0.0

    def check(self, force: bool = False) -> str | None:
        """Why the run must stop for its output, or None; `force` measures the folder now."""
        now = time.monotonic()
        try:
            free = shutil.disk_usage(self.workdir).free
        except OSError:
            return None
        low = free < self.reserve
        if not (low or force) and now < self._next_size:
            return None
        self._next_size = now + self.size_every_s
        size = folder_bytes(self.workdir)
        if size > self.max_bytes:
            return f"it wrote {size / 2**20:.0f} MB, more than max_output_mb ({self.max_bytes / 2**20:.0f} MB)"
        if low and size >= self.reserve:
            return (
                f"it filled the disk: {size / 2**20:.0f} MB written, {free / 2**20:.0f} MB left on "
                f"{self.workdir.anchor} of {self.workdir}"
            )
        return None

    @classmethod
    def of(cls, req: ExecRequest) -> OutputWatch | None:
        return cls(req.workdir, req.max_output_bytes) if req.max_output_bytes else None
