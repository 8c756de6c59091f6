"""glomap: GLOMAP's global structure-from-motion through pycolmap (`pycolmap.global_mapping`), as an offline
baseline beside `colmap`'s incremental one.

The same front end as colmap (SIFT on every `stride`-th rectified frame, sequential matching) and the same output
(the largest model's registered images as camera-to-world TUM poses at the frames' original timestamps; no model
is `not_initialized`); the mapping is global: rotation averaging over the view graph, global positioning of
cameras and points, then bundle adjustment, with the view's intrinsics fixed, on the CPU. Runs as its own process
(`python -m slamrun.methods.colmap.process --mapper global ...`), its thread count following the CPUs it is pinned to.
"""

from __future__ import annotations

from pathlib import Path

from pydantic import BaseModel, ConfigDict, Field

from slamrun.datasets.view import PreparedView, Profile
from slamrun.methods.base import Method, PythonProcess, folder_name, strided


class GlomapParams(BaseModel):
    model_config = ConfigDict(extra="forbid")
    stride: int = Field(3, ge=1, description="Use every n-th frame.")
    max_features: int = Field(1024, ge=100, description="SIFT features per image.")
    overlap: int = Field(10, ge=1, description="Sequential matching: neighbours matched per image.")
    max_image_size: int = Field(640, ge=160, description="Images are downscaled to this size for SIFT.")
    first_octave: int = Field(0, ge=-1, le=2, description="SIFT first octave (-1 doubles the image: slower).")
    min_num_matches: int = Field(15, ge=5, description="Image pairs with fewer inlier matches are left out.")
    ba_iterations: int = Field(3, ge=1, le=20, description="Rounds of bundle adjustment and retriangulation.")
    seed: int | None = Field(
        None,
        description="Random seed of the global mapper; default: one per trial, from the trial and the campaign's seed "
        "(a fixed value makes every trial the same: identical runs).",
    )


class Glomap(PythonProcess, Method):
    name = folder_name(__name__)  # its folder's
    seed_param = "seed"
    deterministic = True  # measured: identical trials with one seed
    threads = None  # its thread count follows the CPUs it is pinned to
    image = None
    profile = Profile.rectified
    native = True
    modules = ("pycolmap", "numpy", "scipy")
    Params = GlomapParams
    not_initialized_pattern = r"^NOT INITIALIZED"

    def frames_given(self, n: int):
        """Every `stride`-th frame of the view and its last (its process takes those): coverage is of them."""
        return strided(n, self.params.stride)

    def command(self, view: PreparedView, workdir: Path) -> list[str]:
        p = self.params
        return [
            self.python, "-m", "slamrun.methods.colmap.process", "--mapper", "global",
            "--images", str(view.path(view.images_dir)), "--times", str(view.path(view.times)),
            "--camera", str(view.path("camera_pinhole.json")), "--out", str(workdir / self.output_file),
            "--workdir", str(workdir), "--stride", str(p.stride), "--max-features", str(p.max_features),
            "--overlap", str(p.overlap), "--max-image-size", str(p.max_image_size),
            "--first-octave", str(p.first_octave), "--min-num-matches", str(p.min_num_matches),
            "--ba-iterations", str(p.ba_iterations), "--seed", str(p.seed or 0),
        ]  # fmt: skip
