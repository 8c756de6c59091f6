"""`external`: any executable given in the spec, for local builds of a method and for tests.

The argv is a list of strings with placeholders filled from the prepared view and the run's work
directory: {python} {view} {images} {times} {rgb} {images_list} {times_single} {camera} {pcalib}
{vignette} {workdir} {out}. The output is read in the given format with view timestamps.
"""

from __future__ import annotations

import re
import sys
from enum import StrEnum
from pathlib import Path

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator

from slamrun.core.trajectory import Trajectory, read_4x4_matrices, read_kitti, read_timestamped_3x4
from slamrun.datasets.view import PreparedView, Profile
from slamrun.errors import MethodFailure
from slamrun.methods.base import MAX_ARG_BYTES, Method, executable_problem, read_tum_output, require_poses


class OutputFormat(StrEnum):
    tum = "tum"
    kitti = "kitti"  # 12 numbers per frame, one row per view frame
    timestamped_3x4 = "timestamped_3x4"
    matrices_4x4 = "matrices_4x4"


class ExternalParams(BaseModel):
    model_config = ConfigDict(extra="forbid")
    argv: list[str] = Field(min_length=1, description="Command and arguments, with {placeholders}.")
    output: str = Field("trajectory.txt", description="Output file, relative to the work directory.")
    format: OutputFormat = Field(OutputFormat.tum, description="Format of the output file.")
    profile: Profile = Field(Profile.native, description="Prepared view the executable consumes.")
    cwd: str | None = Field(None, description="Working directory (default: the run's work directory).")
    env: dict[str, str] = Field(default_factory=dict, description="Environment variables set for the process.")
    image: str | None = Field(
        None, description="Docker image to run argv in with backend: docker (paths then are /data and /work)."
    )
    not_initialized_pattern: str | None = Field(None, description="Log regex meaning 'never initialised'.")
    lost_pattern: str | None = Field(None, description="Log regex meaning 'lost'.")
    infra_pattern: str | None = Field(
        None, description="Log regex meaning the machine lacks what it needs (not charged to the method)."
    )

    @field_validator("not_initialized_pattern", "lost_pattern", "infra_pattern")
    @classmethod
    def _a_regular_expression(cls, value: str | None) -> str | None:
        if value is not None:
            try:
                re.compile(value)
            except re.error as exc:
                raise ValueError(f"{value!r} is not a regular expression ({exc})") from None
        return value


class External(Method):
    native = True
    Params = ExternalParams

    @property
    def profile(self) -> Profile:  # type: ignore[override]
        return self.params.profile

    @property
    def image(self) -> str | None:  # type: ignore[override]
        return self.params.image

    def problems(self, backend: str) -> list[str]:
        out = []
        if backend == "docker" and not self.params.image:
            out.append("external runs in Docker only with params.image (the image to run argv in)")
        known = self.placeholders(
            PreparedView(Path("/data"), "s", "forward", Profile.native, 1, 0, 1, 1, 1, None), Path("/w")
        )
        for i, arg in enumerate(self.params.argv):
            if len(arg.encode()) >= MAX_ARG_BYTES:
                out.append(f"params.argv[{i}]: {len(arg.encode())} bytes; no process takes an argument that long")
                continue
            try:
                arg.format_map(known)
            except (KeyError, ValueError, IndexError) as exc:
                out.append(
                    f"params.argv[{i}]: {arg[:60]!r}: bad placeholder {exc} (known: {', '.join(sorted(known))}; "
                    "write {{ and }} for literal braces)"
                )
        return out

    def executable_problems(self, backend: str) -> list[str]:
        """argv[0] as the local backend starts it, when it names its program without placeholders ({python} aside)."""
        program = self.params.argv[0]
        if backend != "local" or program == "{python}" or "{" in program:
            return []
        why = executable_problem(program)
        return [f"params.argv[0]: {why}"] if why else []

    @property
    def not_initialized_pattern(self) -> str | None:  # type: ignore[override]
        return self.params.not_initialized_pattern

    @property
    def lost_pattern(self) -> str | None:  # type: ignore[override]
        return self.params.lost_pattern

    @property
    def infra_pattern(self) -> str | None:  # type: ignore[override]
        return self.params.infra_pattern

    def placeholders(self, view: PreparedView, workdir: Path) -> dict[str, str]:
        v = view
        return {
            "python": sys.executable,
            "view": str(v.root),
            "images": str(v.path(v.images_dir)),
            "times": str(v.path(v.times)),
            "rgb": str(v.path(v.rgb)),
            "images_list": str(v.path(v.images_list)),
            "times_single": str(v.path(v.times_single)),
            "camera": str(v.path(v.camera)),
            "pcalib": str(v.path(v.pcalib)),
            "vignette": str(v.path(v.vignette)),
            "workdir": str(workdir),
            "out": str(workdir / self.params.output),
        }

    def environment(self) -> dict[str, str]:
        return dict(self.params.env)

    def command(self, view: PreparedView, workdir: Path) -> list[str]:
        values = self.placeholders(view, workdir)
        try:
            return [arg.format_map(values) for arg in self.params.argv]
        except KeyError as exc:
            raise MethodFailure("crashed", f"unknown placeholder {exc} in argv; known: {sorted(values)}") from None

    def read_trajectory(self, workdir: Path, view: PreparedView) -> Trajectory:
        path = workdir / self.params.output
        fmt = self.params.format
        if fmt is OutputFormat.tum:
            traj = read_tum_output(path)
        elif not path.exists():
            raise MethodFailure("no_output", f"the method wrote no {path.name}")
        elif fmt is OutputFormat.kitti:
            traj = read_kitti(path, view.view_timestamps())
        elif fmt is OutputFormat.timestamped_3x4:
            traj = read_timestamped_3x4(path)
        else:
            traj = read_4x4_matrices(path, np.asarray(view.view_timestamps()))
        return view.to_original(require_poses(traj, path))
