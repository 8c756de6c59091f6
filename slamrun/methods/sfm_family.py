"""The structure-from-motion family (colmap, glomap): pycolmap's SIFT on every `stride`-th rectified frame and
sequential matching, then a mapper (incremental or global), all in one process of slamrun's own
(slamrun/methods/sfm_process.py); the largest model's registered images are camera-to-world TUM poses at the frames'
original timestamps, no model is `not_initialized`. Each member's folder declares its mapper and parameters."""

from __future__ import annotations

from pathlib import Path
from typing import Any, ClassVar

from pydantic import BaseModel, ConfigDict, Field

from slamrun.datasets.view import PreparedView, Profile
from slamrun.methods.base import Method, PythonProcess, strided, trial_seed_param

PROCESS = "slamrun.methods.sfm_process"


class SfmParams(BaseModel):
    model_config = ConfigDict(extra="forbid")
    stride: int = Field(3, ge=1, description="Use every n-th frame.")
    max_features: int = Field(1024, ge=100, description="SIFT features per image.")
    overlap: int = Field(5, ge=1, description="Sequential matching: neighbours matched per image.")
    max_image_size: int = Field(640, ge=160, description="Images are downscaled to this size for SIFT.")
    first_octave: int = Field(0, ge=-1, le=2, description="SIFT first octave (-1 doubles the image: slower).")


def mapper_seed_param(seeds: str) -> Any:
    """A member's `seed` parameter (the family's seed_param), `seeds` its mapper's seed: the family is deterministic,
    a fixed one makes its trials identical."""
    return trial_seed_param(seeds, "a fixed value makes every trial the same: identical runs")


class SfmFamily(PythonProcess, Method):
    """The adapter the family shares: its process, the frames it is given, the front end's arguments."""

    seed_param = "seed"
    deterministic = True  # measured: identical trials with one seed
    threads = None  # its thread count follows the CPUs it is pinned to
    image = None
    profile = Profile.rectified
    native = True
    modules = ("pycolmap", "numpy", "scipy")
    not_initialized_pattern = r"^NOT INITIALIZED"
    mapper: ClassVar[str]  # the process's --mapper

    def frames_given(self, n: int):
        """Every `stride`-th frame of the view and its last (its process takes those): coverage is of them."""
        return strided(n, self.params.stride)

    def command(self, view: PreparedView, workdir: Path) -> list[str]:
        p = self.params
        return [
            self.python, "-m", PROCESS, "--mapper", self.mapper,
            "--images", str(view.path(view.images_dir)), "--times", str(view.path(view.times)),
            "--camera", str(view.path("camera_pinhole.json")), "--out", str(workdir / self.output_file),
            "--workdir", str(workdir), "--stride", str(p.stride), "--max-features", str(p.max_features),
            "--overlap", str(p.overlap), "--max-image-size", str(p.max_image_size),
            "--first-octave", str(p.first_octave), *self.mapper_args(), "--seed", str(p.seed or 0),
        ]  # fmt: skip

    def mapper_args(self) -> list[str]:
        """The member's own mapper settings."""
        return []
