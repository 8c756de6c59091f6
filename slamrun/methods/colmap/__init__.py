"""colmap: COLMAP's incremental structure-from-motion through pycolmap, as a (slow) offline baseline.

Feature extraction, sequential matching and incremental mapping over the rectified frames (every
`stride`-th); the largest model's registered images become camera-to-world TUM poses. No model means
`not_initialized`. Runs as its own process (`python -m slamrun.methods.colmap.process ...`) so the runner can time it,
measure it and stop it like any other method; its thread count follows the CPUs it is pinned to.
"""

from __future__ import annotations

from pathlib import Path

from pydantic import BaseModel, ConfigDict, Field

from slamrun.datasets.view import PreparedView, Profile
from slamrun.methods.base import Method, PythonProcess, folder_name, strided


class ColmapParams(BaseModel):
    model_config = ConfigDict(extra="forbid")
    stride: int = Field(3, ge=1, description="Use every n-th frame.")
    max_features: int = Field(1024, ge=100, description="SIFT features per image.")
    overlap: int = Field(5, ge=1, description="Sequential matching: neighbours matched per image.")
    max_image_size: int = Field(640, ge=160, description="Images are downscaled to this size for SIFT.")
    global_ba_every: int = Field(20, ge=1, description="Global bundle adjustment after this many new images.")
    seed: int | None = Field(
        None,
        description="Mapper random seed; default: one per trial, from the trial and the campaign's seed "
        "(a fixed value makes every trial the same: identical runs).",
    )
    first_octave: int = Field(0, ge=-1, le=2, description="SIFT first octave (-1 doubles the image: slower).")


class Colmap(PythonProcess, Method):
    name = folder_name(__name__)  # its folder's
    seed_param = "seed"
    deterministic = True  # measured: identical trials with one seed
    threads = None  # its thread count follows the CPUs it is pinned to
    image = None
    profile = Profile.rectified
    native = True
    modules = ("pycolmap", "numpy", "scipy")
    Params = ColmapParams
    not_initialized_pattern = r"^NOT INITIALIZED"

    def frames_given(self, n: int):
        """Every `stride`-th frame of the view and its last (its process takes those): coverage is of them."""
        return strided(n, self.params.stride)

    def command(self, view: PreparedView, workdir: Path) -> list[str]:
        p = self.params
        return [
            self.python, "-m", "slamrun.methods.colmap.process",
            "--images", str(view.path(view.images_dir)), "--times", str(view.path(view.times)),
            "--camera", str(view.path("camera_pinhole.json")), "--out", str(workdir / self.output_file),
            "--workdir", str(workdir), "--stride", str(p.stride), "--max-features", str(p.max_features),
            "--overlap", str(p.overlap), "--max-image-size", str(p.max_image_size),
            "--global-ba-every", str(p.global_ba_every), "--seed", str(p.seed or 0),
            "--first-octave", str(p.first_octave),
        ]  # fmt: skip
