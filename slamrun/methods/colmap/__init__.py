"""colmap: COLMAP's incremental structure-from-motion through pycolmap, as a (slow) offline baseline.

Feature extraction, sequential matching and incremental mapping over the rectified frames (every
`stride`-th); the largest model's registered images become camera-to-world TUM poses. No model means
`not_initialized`. Runs as its own process (`python -m slamrun.methods.sfm_process --mapper incremental ...`, the
structure-from-motion family's) so the runner can time it,
measure it and stop it like any other method; its thread count follows the CPUs it is pinned to.
"""

from __future__ import annotations

from pydantic import Field

from slamrun.methods.sfm_family import SfmFamily, SfmParams, mapper_seed_param


class ColmapParams(SfmParams):
    global_ba_every: int = Field(20, ge=1, description="Global bundle adjustment after this many new images.")
    seed: int | None = mapper_seed_param("Mapper random seed")


class Colmap(SfmFamily):
    Params = ColmapParams
    mapper = "incremental"

    def mapper_args(self) -> list[str]:
        return ["--global-ba-every", str(self.params.global_ba_every)]
