"""glomap: GLOMAP's global structure-from-motion through pycolmap (`pycolmap.global_mapping`), as an offline
baseline beside `colmap`'s incremental one.

The same front end as colmap (SIFT on every `stride`-th rectified frame, sequential matching) and the same output
(the largest model's registered images as camera-to-world TUM poses at the frames' original timestamps; no model
is `not_initialized`); the mapping is global: rotation averaging over the view graph, global positioning of
cameras and points, then bundle adjustment, with the view's intrinsics fixed, on the CPU. Runs as its own process
(`python -m slamrun.methods.sfm_process --mapper global ...`, the structure-from-motion family's), its thread count
following the CPUs it is pinned to.
"""

from __future__ import annotations

from pydantic import Field

from slamrun.methods.sfm_family import SfmFamily, SfmParams, mapper_seed_param


class GlomapParams(SfmParams):
    overlap: int = Field(10, ge=1, description="Sequential matching: neighbours matched per image.")
    min_num_matches: int = Field(15, ge=5, description="Image pairs with fewer inlier matches are left out.")
    ba_iterations: int = Field(3, ge=1, le=20, description="Rounds of bundle adjustment and retriangulation.")
    seed: int | None = mapper_seed_param("Random seed of the global mapper")


class Glomap(SfmFamily):
    Params = GlomapParams
    mapper = "global"

    def mapper_args(self) -> list[str]:
        p = self.params
        return ["--min-num-matches", str(p.min_num_matches), "--ba-iterations", str(p.ba_iterations)]
