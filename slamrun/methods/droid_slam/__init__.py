"""DROID-SLAM (princeton-vl/DROID-SLAM @ 2dfd39f, BSD-3, with lietorch @ 7f68764), on the rectified view; it needs a
GPU.

Runs as its own process, `python -m slamrun.methods.droid_slam.process ...` (its runner: every `stride`-th frame of the
view tracked, as demo.py does; then DROID's terminate() (two global bundle adjustments and its trajectory filler) given
EVERY frame of the view, so every input frame gets a pose, at its original timestamp, as TUM camera-to-world). Its CUDA
extensions (lietorch_backends, droid_backends) come from one of:
- `backend: local`: a native build in slamrun's cache, compiled once by `slamrun native-build droid_slam` from the
  pinned archives with slamrun/methods/droid_slam/image/patches.py, by and for the Python that runs slamrun (PyTorch
  with CUDA, nvcc);
- `backend: docker|podman`: the image slamrun/droid_slam (slamrun/methods/droid_slam/image/Dockerfile, `slamrun images
--method
  droid_slam`): the same archives and patches, compiled without a GPU for compute capability 7.5 to 9.0, its network
  in /opt/droid_slam/weights.
The network (droid.pth) is the one the build holds (`--weights droid.pth=FILE|URL#sha256=HEX`, or `--standin-model`: a
random-init network from a fixed seed, plumbing only, accuracy meaningless; build.json and every run's log say which),
or params.weights. The parameters are demo.py's options with its defaults.
"""

from __future__ import annotations

from pathlib import Path

from pydantic import BaseModel, ConfigDict, Field

from slamrun.datasets.view import Profile
from slamrun.methods.declare import NativeMethod, Source, Weights
from slamrun.methods.libraries import LIETORCH
from slamrun.methods.native_gpu import NativeGpuMethod, build_param, torch_seed_param, weights_param

IMAGE_BUILD = "/opt/droid_slam"
WEIGHTS_NAME = "droid.pth"
# The stand-in (image/standin_model.py, the same arguments as its network.sh): its flow head (update.delta) scaled to a
# mean flow of 8 px on random inputs, above the motion filter's 2.4 px
STANDIN_SEED = 0
STANDIN_FLOW_PX = 8.0
IMAGE = Path(__file__).resolve().parent / "image"  # its image's recipe; the native build's patches are the image's
IMAGE_WEIGHTS = f"{IMAGE_BUILD}/weights/{WEIGHTS_NAME}"  # where the image holds its network (network.sh)


class DroidSlamParams(BaseModel):
    model_config = ConfigDict(extra="forbid")
    weights: str | None = weights_param(WEIGHTS_NAME)
    build: str | None = build_param("droid_slam")
    stride: int = Field(3, ge=1, description="Track every n-th frame (demo.py --stride: 3); every frame gets a pose.")
    buffer: int = Field(512, ge=16, description="Most keyframes held on the GPU (demo.py --buffer: 512).")
    beta: float = Field(0.3, ge=0, description="Weight of translation against rotation in frame distances (0.3).")
    filter_thresh: float = Field(2.4, ge=0, description="Mean flow (px) before a frame is kept (demo.py: 2.4).")
    warmup: int = Field(8, ge=2, description="Keyframes before the system initialises (demo.py --warmup: 8).")
    keyframe_thresh: float = Field(4.0, ge=0, description="Distance below which a keyframe is dropped (4.0).")
    frontend_thresh: float = Field(16.0, ge=0, description="Frontend edges between frames within this distance (16).")
    frontend_window: int = Field(25, ge=1, description="Frontend optimisation window, keyframes (demo.py: 25).")
    frontend_radius: int = Field(2, ge=0, description="Frontend edges forced between frames this close (demo.py: 2).")
    frontend_nms: int = Field(1, ge=0, description="Non-maximum suppression of frontend edges (demo.py: 1).")
    backend_thresh: float = Field(22.0, ge=0, description="Backend edges between frames within this distance (22).")
    backend_radius: int = Field(2, ge=0, description="Backend edges forced between frames this close (demo.py: 2).")
    backend_nms: int = Field(3, ge=0, description="Non-maximum suppression of backend edges (demo.py: 3).")
    upsample: bool = Field(False, description="Upsample depth maps in the factor graph (demo.py --upsample: off).")
    motion_damping: float = Field(
        0.0, ge=0, le=1, description="Damped constant-velocity guess of the next pose (demo.py sets none: 0)."
    )
    seed: int | None = torch_seed_param()


class DroidSlam(NativeGpuMethod):
    seed_param = "seed"
    threads = 2  # the network's process and its frame reader, beside the GPU
    # with its submodules at the commits it records: thirdparty/lietorch (Lie groups on PyTorch, compiled with it)
    # and thirdparty/pytorch_scatter, not compiled (its scatter_sum and scatter_mean, pure Python there, are
    # dpvo/image/torch_scatter_compat.py's; the tests check them against it)
    sources = (
        Source(
            "droid_slam",
            "princeton-vl/DROID-SLAM",
            "2dfd39f0dcad44012ca7bbb8aa70b55edbfa9c99",
            sha256="03488a61c5741994523bee7a52ec1a9c0b17175e8fd5a8cf16de4c5fdebd8d91",
            tree="e7828067e7d5343e85473a5bda4f9b62b5dbcd19cfeb83ca8512334ea717e6ea",
        ),
        LIETORCH,
        Source(
            "pytorch_scatter",
            "rusty1s/pytorch_scatter",
            "6cf77c420f837a427b0d57965e414d68c1bd89ec",
            sha256="97e3bddb38fc873a37a8a9f35b1cb08e268ee96effd25dee68dbb9389681e87d",
            tree="fa24f4f0b8da8c8b98689cdb58b4e1d95489f1a9a93486dd825f8b1e1316ec1f",
        ),
    )
    network = Weights(
        "droid.pth",
        "DROID-SLAM's tools/download_model.sh (`gdown 1PpqVt1H4maBa_GbPJp4NwxRsd9jk-elh`, a Google Drive file: "
        "https://drive.google.com/uc?id=1PpqVt1H4maBa_GbPJp4NwxRsd9jk-elh)",
        standin=True,
        arg="DROID_MODEL",
    )
    native_build = NativeMethod(
        label="DROID-SLAM",
        source="droid_slam",
        parts=(("lietorch", "thirdparty/lietorch"),),
        patches=IMAGE / "patches.py",
        setups=(("thirdparty/lietorch", ("lietorch_backends",)), (".", ("droid_backends",))),
        import_path=("thirdparty/lietorch", "droid_slam", "."),
        weights_name=WEIGHTS_NAME,
        standin=IMAGE / "standin_model.py",
        standin_args=(str(STANDIN_SEED), str(STANDIN_FLOW_PX)),
        standin_note=f"random init, torch seed {STANDIN_SEED}, {{out}} for a mean flow of {STANDIN_FLOW_PX:g} px",
    )
    profile = Profile.rectified
    Params = DroidSlamParams
    not_initialized_pattern = r"^NOT INITIALIZED"
    process = f"{__name__}.process"  # its folder's process.py (`python -m`), given these params as one JSON object
    image_build = IMAGE_BUILD
    weights_name = WEIGHTS_NAME
