"""What every backend takes and gives back."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

from runner.datasets.view import PreparedView


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


@dataclass(frozen=True)
class ExecResult:
    exit_code: int | None
    wall_s: float
    timed_out: bool = False
    oom: bool = False
    cancelled: bool = False
    log_truncated: bool = False
    resources: dict = field(default_factory=dict)


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

    def leftovers(self, campaign: str) -> list:
        """Runs of this campaign that a killed runner or a lost daemon left behind, for `collect` (containers)."""

    def collect(self, leftover, log_path: Path, log_cap_bytes: int, n_frames: int) -> ExecResult | None:
        """The result of a leftover that ended by itself; None while it runs or when it never started."""

    def close(self) -> None:
        """Release what the backend holds (a cluster client)."""


class Defaults:
    """The optional features' neutral forms, for backends that have no images, leftovers or resources."""

    engine: str | None = None

    def describe_image(self, tag: str) -> dict | None:
        return None

    def leftovers(self, campaign: str) -> list:
        return []

    def collect(self, leftover, log_path: Path, log_cap_bytes: int, n_frames: int) -> ExecResult | None:
        return None

    def close(self) -> None:
        pass


def supervise(
    wait_step: Callable[[float], bool], t0: float, timeout_s: float, cancel: threading.Event
) -> tuple[bool, bool]:
    """Wait for a run until it ends, its wall-clock timeout passes or `cancel` is set.

    `wait_step(remaining_s)` waits a short while and returns True once the process has ended.
    Returns (timed_out, cancelled).
    """
    while True:
        remaining = t0 + timeout_s - time.monotonic()
        if remaining <= 0:
            return True, False
        if cancel.is_set():
            return False, True
        if wait_step(remaining):
            return False, False
