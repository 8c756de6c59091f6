"""reference_vo (adapter): this project's own monocular VO (OpenCV + NumPy/SciPy), the harness's self-test and baseline.

Runs as its own process: `python -m slamrun.methods.reference_vo --images ... --times ... --camera ... --out ...`.
"""

from __future__ import annotations

from pathlib import Path

from pydantic import BaseModel, ConfigDict, Field

from slamrun.datasets.view import PreparedView, Profile
from slamrun.methods.base import Method, PythonProcess


class ReferenceVOParams(BaseModel):
    model_config = ConfigDict(extra="forbid")
    max_corners: int = Field(500, ge=50, le=5000, description="Corners tracked per frame.")
    seed: int = Field(
        0,
        description="OpenCV's RNG seed. OpenCV's RANSAC seeds itself (opencv/opencv#24835: reproducible by design), "
        "so runs with any two seeds are identical (measured): kept so that specs naming it stay valid.",
    )


class ReferenceVO(PythonProcess, Method):
    deterministic = True  # identical runs whatever the seed (its RANSACs seed themselves): trials are copies
    verified = False  # slamrun's own baseline: its tests check it against known answers, `slamrun verify` does not
    profile = Profile.rectified
    native = True
    modules = ("numpy", "scipy", "cv2")
    Params = ReferenceVOParams
    not_initialized_pattern = r"^NOT INITIALIZED"
    lost_pattern = r"^LOST"

    def command(self, view: PreparedView, workdir: Path) -> list[str]:
        return [
            self.python, "-m", __name__,  # its own folder's __main__.py
            "--images", str(view.path(view.images_dir)),
            "--times", str(view.path(view.times)),
            "--camera", str(view.path(view.camera)),
            "--out", str(workdir / self.output_file),
            "--max-corners", str(self.params.max_corners),
            "--seed", str(self.params.seed),
        ]  # fmt: skip
