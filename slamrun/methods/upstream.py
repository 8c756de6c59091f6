"""What the study's ten methods share: an upstream binary in a Docker image, or a local build of it."""

from __future__ import annotations

import copy
from typing import ClassVar

from pydantic import BaseModel, ConfigDict, Field

from slamrun.datasets.view import PreparedView
from slamrun.methods.base import Method


class UpstreamParams(BaseModel):
    model_config = ConfigDict(extra="forbid")
    executable: str | None = Field(
        None, description="Path of a local build's binary: the local backend runs it instead of the image's."
    )
    loop_closure: bool = Field(False, description="Loop closure on (off by default, so drift is measured alike).")


class UpstreamMethod(Method):
    """A method built from its authors' repository. `binary` is its path inside the image."""

    binary: ClassVar[str]
    Params = UpstreamParams
    backend: str = "docker"

    def for_backend(self, backend: str) -> Method:
        method = copy.copy(self)
        method.backend = backend
        return method

    def problems(self, backend: str) -> list[str]:
        if backend == "local" and not self.params.executable:
            return [
                f"{self.name} runs natively only from a local build: give params.executable, or use backend: docker"
            ]
        if self.params.loop_closure and self.loop_closure_switch is None:
            return [f"{self.name} has no loop closure to turn on"]
        return []

    def exe(self) -> str:
        return self.params.executable or self.binary


class GpuOptionalParams(BaseModel):
    """Parameters of the learning-based methods: a network file, and the GPU as an option."""

    model_config = ConfigDict(extra="forbid")
    gpu: bool = Field(False, description="Run the network on a GPU (TensorFlow 1.x: CUDA 9/10 GPUs only).")


class GpuOptional:
    """Mixin: CPU inference by default, a GPU requested only when params.gpu is set."""

    gpu_capable = True

    @property
    def needs_gpu(self) -> bool:
        return self.params.gpu

    def cpu_environment(self) -> dict[str, str]:
        return {} if self.params.gpu else {"CUDA_VISIBLE_DEVICES": ""}


def fps_of(view: PreparedView) -> float:
    """Mean frame rate of a view (from its first and last timestamps; reads no file)."""
    span = view.t_last - view.t_first
    return (view.n_frames - 1) / span if view.n_frames > 1 and span > 0 else 30.0


def pinhole_of(view: PreparedView) -> tuple[float, float, float, float]:
    if view.pinhole is None:
        raise ValueError(f"{view.root}: not a rectified view; this method needs the rectified profile")
    return view.pinhole
