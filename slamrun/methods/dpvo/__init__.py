"""DPVO (princeton-vl/DPVO @ 859bbbf, Deep Patch Visual Odometry, MIT), on the rectified view; it needs a GPU.

Runs as its own process, `python -m slamrun.methods.dpvo.process ...` (its runner: the view's frames in order, DPVO's
own settings, every fed frame's pose at its original timestamp as TUM; DPVO interpolates the frames it drops as
non-keyframes from their keyframe's pose, as its demo.py does). Its CUDA extensions (cuda_corr, cuda_ba,
lietorch_backends) come from one of:
- `backend: local`: a native build in slamrun's cache, compiled once by `slamrun native-build dpvo` from the pinned
  archive with slamrun/methods/dpvo/image/patches.py, by and for the Python that runs slamrun (PyTorch with CUDA, nvcc);
- `backend: docker|podman`: the image slamrun/dpvo (slamrun/methods/dpvo/image/Dockerfile, `slamrun images --method
dpvo`): the same
  archive and patches, compiled without a GPU for compute capability 7.5 to 9.0, its network in /opt/dpvo/weights.
The network (dpvo.pth) is the one the build holds (`--weights dpvo.pth=FILE|URL#sha256=HEX`, or `--standin-model`: a
random-init network from a fixed seed, plumbing only, accuracy meaningless; build.json and every run's log say
which), or params.weights. The parameters are DPVO's config/default.yaml and demo.py defaults.
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

from slamrun.datasets.view import Profile
from slamrun.methods.base import strided
from slamrun.methods.declare import NativeMethod, Source, Weights, added
from slamrun.methods.native_gpu import NativeGpuMethod, build_param, torch_seed_param, weights_param

IMAGE_WEIGHTS = (
    "/opt/dpvo/weights/dpvo.pth"  # where the image holds its network (slamrun/methods/dpvo/image/network.sh)
)
IMAGE_BUILD = "/opt/dpvo"
WEIGHTS_NAME = "dpvo.pth"
STANDIN_SEED = 0  # the same as image/network.sh's
# A random network's flow head gives sub-pixel updates, which DPVO's motion probe (median >= 2 px before it starts)
# takes for a still camera: it would never initialise. The stand-in's flow head (update.d, Linear(384, 2)) is scaled
# so that its updates are a few pixels and the whole pipeline runs (patches, BA, keyframes, terminate).
STANDIN_FLOW_GAIN = 16.0
IMAGE = Path(__file__).resolve().parent / "image"  # its image's recipe; the native build's patches are the image's
SINCE_DPV_SLAM = added("2026-11-29")  # DPVO's runs made before keep their settings' name (engine.plan.hashed)


class DpvoParams(BaseModel):
    model_config = ConfigDict(extra="forbid")
    weights: str | None = weights_param(WEIGHTS_NAME)
    build: str | None = build_param("dpvo")
    stride: int = Field(2, ge=1, description="Feed every n-th frame (demo.py --stride: 2); poses of the fed frames.")
    patches_per_frame: int = Field(96, ge=4, le=1024, description="PATCHES_PER_FRAME (config/default.yaml: 96).")
    removal_window: int = Field(22, ge=2, description="REMOVAL_WINDOW: frames an edge lives (default.yaml: 22).")
    optimization_window: int = Field(10, ge=1, description="OPTIMIZATION_WINDOW: frames in local BA (default: 10).")
    patch_lifetime: int = Field(13, ge=1, description="PATCH_LIFETIME: frames a patch is tracked (default.yaml: 13).")
    keyframe_thresh: float = Field(15.0, ge=0, description="KEYFRAME_THRESH: flow (px) below which a frame is dropped.")
    keyframe_index: int = Field(4, ge=1, description="KEYFRAME_INDEX: which recent frame is tested (config.py: 4).")
    motion_model: Literal["DAMPED_LINEAR", "LAST_POSE"] = Field(
        "DAMPED_LINEAR", description="MOTION_MODEL: DAMPED_LINEAR (default.yaml), or the last pose as the guess."
    )
    motion_damping: float = Field(0.5, ge=0, le=1, description="MOTION_DAMPING (default.yaml: 0.5).")
    mixed_precision: bool = Field(True, description="MIXED_PRECISION: half-precision network (default.yaml: true).")
    centroid_sel_strat: Literal["RANDOM", "GRADIENT_BIAS"] = Field(
        "RANDOM", description="CENTROID_SEL_STRAT: where patches are taken (default.yaml: RANDOM)."
    )
    buffer_size: int = Field(4096, ge=16, description="BUFFER_SIZE: most keyframes kept (config.py: 4096).")
    # DPV-SLAM (ECCV 2024) is DPVO with its proximity loop closure: `--opts LOOP_CLOSURE True` (README: DPV-SLAM)
    loop_closure: bool = Field(
        False,
        description="LOOP_CLOSURE: DPV-SLAM's proximity loop closure and global BA (config.py: false); "
        "the classical, image-retrieval loop closure (CLASSIC_LOOP_CLOSURE) is not offered.",
        json_schema_extra=SINCE_DPV_SLAM,
    )
    backend_thresh: float = Field(
        64.0, gt=0, description="BACKEND_THRESH: flow (px) under which an old patch makes a loop edge (config.py: 64).",
        json_schema_extra=SINCE_DPV_SLAM,
    )  # fmt: skip
    max_edge_age: int = Field(
        1000, ge=1, description="MAX_EDGE_AGE: frames back a loop edge may reach (config.py: 1000).",
        json_schema_extra=SINCE_DPV_SLAM,
    )  # fmt: skip
    global_opt_freq: int = Field(
        15, ge=1, description="GLOBAL_OPT_FREQ: frames between loop-edge searches (config.py: 15).",
        json_schema_extra=SINCE_DPV_SLAM,
    )  # fmt: skip
    seed: int | None = torch_seed_param()


class Dpvo(NativeGpuMethod):
    seed_param = "seed"
    threads = 2  # the network's process and its frame reader (PREFETCH frames ahead), beside the GPU
    sources = (
        Source(
            "dpvo",
            "princeton-vl/DPVO",
            "859bbbfdac6c6185f345003b3c473901fcd13ace",
            sha256="40c43ebe3be51e5c6e1c9d1a0d866b84b8e285093ce132d8b53ae97bf8b49dfb",
            tree="4372b2d0909e07a42cf662c73ae98abe687b1a17733fb4dbcb872b60ca36b4a9",
        ),
    )
    network = Weights(
        "dpvo.pth",
        "DPVO's download_models_and_data.sh: models.zip (https://www.dropbox.com/s/nap0u8zslspdwm4/models.zip), "
        "which holds dpvo.pth",
        standin=True,
        arg="DPVO_MODEL",
    )
    native_build = NativeMethod(
        label="DPVO",
        source="dpvo",
        parts=(),
        patches=IMAGE / "patches.py",
        setups=((".", ("cuda_corr", "cuda_ba", "lietorch_backends")),),
        import_path=(".",),
        weights_name=WEIGHTS_NAME,
        standin=IMAGE / "standin_model.py",  # the stand-in network, the image's too
        standin_args=(str(STANDIN_SEED), str(STANDIN_FLOW_GAIN)),
        standin_note=f"random init, torch seed {STANDIN_SEED}, flow head x{STANDIN_FLOW_GAIN:g}",
    )
    profile = Profile.rectified
    Params = DpvoParams
    not_initialized_pattern = r"^NOT INITIALIZED"
    process = f"{__name__}.process"  # its folder's process.py (`python -m`), given these params as one JSON object
    image_build = IMAGE_BUILD
    weights_name = WEIGHTS_NAME
    variants = {"dpv_slam": {"loop_closure": True}}  # DPV-SLAM (ECCV 2024): DPVO with its proximity loop closure

    def frames_given(self, n: int):
        """Every `stride`-th frame of the view and its last (its process takes those): coverage is of them."""
        return strided(n, self.params.stride)
