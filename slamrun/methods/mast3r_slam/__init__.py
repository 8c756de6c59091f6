"""MASt3R-SLAM (rmurai0610/MASt3R-SLAM @ b0ae540, CVPR 2025, CC BY-NC-SA 4.0; with lietorch @ 7f68764), dense SLAM on
MASt3R's two-view 3D priors, on the rectified view; it needs a GPU.

Runs as its own process, `python -m slamrun.methods.mast3r_slam.process ...` (its runner: every `subsample`-th frame
of the view, as its evaluation configs take them, tracked against the last keyframe; its backend, upstream main.py's
run_backend itself, in a thread beside the frontend, in the order its single_thread evaluation mode gives their steps;
a pose for every frame it tracked: a keyframe's optimised pose, or a tracked frame's pose relative to its keyframe
carried by that keyframe's final pose; camera-to-world SE(3) as TUM, at the frames' original timestamps). Calibrated
from the view's pinhole camera by default (config/eval_calib.yaml), uncalibrated with `calibrated: false`
(eval_no_calib.yaml). Its CUDA extensions (lietorch_backends, mast3r_slam_backends, croco's curope, asmk's hamming)
come from one of:
- `backend: local`: a native build in slamrun's cache, compiled once by `slamrun native-build mast3r_slam` from the
  pinned archives with slamrun/methods/mast3r_slam/image/patches.py, by and for the Python that runs slamrun;
- `backend: docker|podman`: the image slamrun/mast3r_slam (image/Dockerfile, `slamrun images --method mast3r_slam`): the
  same archives and patches, compiled without a GPU for compute capability 7.5 to 9.0.
Its weights are three files, as its README's checkpoints/ folder holds them (the MASt3R network, the retrieval head and
its codebook): given (`--weights NAME=FILE` for each), or an untrained stand-in with the same architecture from a fixed
seed (`--standin-model`: plumbing only, accuracy meaningless); or params.weights, the MASt3R checkpoint's path with the
other two beside it under their published names. The GPU memory it needs at the sequence's resolution is checked
before the network loads: too little is said in one line and charged to the machine, not the method.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from slamrun.datasets.view import Profile
from slamrun.methods.declare import NativeMethod, Source, Weights
from slamrun.methods.libraries import LIETORCH
from slamrun.methods.native_gpu import NativeGpuMethod, build_param, torch_seed_param, weights_param

IMAGE_BUILD = "/opt/mast3r_slam"
WEIGHTS_NAME = "MASt3R_ViTLarge_BaseDecoder_512_catmlpdpt_metric.pth"
# the retrieval head and its codebook, beside the network under these names (mast3r_utils.load_retriever and
# mast3r/retrieval/processor.py find the codebook by the retrieval file's name)
RETRIEVAL_NAME = "MASt3R_ViTLarge_BaseDecoder_512_catmlpdpt_metric_retrieval_trainingfree.pth"
CODEBOOK_NAME = "MASt3R_ViTLarge_BaseDecoder_512_catmlpdpt_metric_retrieval_codebook.pkl"
STANDIN_SEED = 0
IMAGE = Path(__file__).resolve().parent / "image"
CROCO = "thirdparty/mast3r/dust3r/croco"


class Mast3rSlamParams(BaseModel):
    model_config = ConfigDict(extra="forbid")
    weights: str | None = weights_param(WEIGHTS_NAME)
    build: str | None = build_param("mast3r_slam")
    calibrated: bool = Field(
        True, description="Use the view's pinhole camera (config/eval_calib.yaml); false: uncalibrated (eval_no_calib)."
    )
    subsample: int = Field(2, ge=1, description="Take every n-th frame (its evaluation configs' dataset.subsample: 2).")
    buffer: int = Field(512, ge=8, description="Keyframes held on the GPU (SharedKeyframes' buffer: 512).")
    match_frac_thresh: float = Field(
        0.333, gt=0, le=1, description="tracking.match_frac_thresh: a new keyframe below this match fraction (0.333)."
    )
    min_match_frac: float = Field(
        0.05, ge=0, le=1, description="tracking.min_match_frac: below it a frame is skipped and relocalised (0.05)."
    )
    retrieval_k: int = Field(3, ge=1, description="retrieval.k: loop candidates per keyframe (config/base.yaml: 3).")
    retrieval_min_thresh: float = Field(
        5e-3, ge=0, description="retrieval.min_thresh: least retrieval score of a loop candidate (5e-3)."
    )
    seed: int | None = torch_seed_param()


class Mast3rSlam(NativeGpuMethod):
    seed_param = "seed"
    threads = 2  # the frontend and its backend's thread, beside the GPU
    # what decides its results natively beside PyTorch: the image normalisation and resize, the retrieval index
    modules = ("torch", "torchvision", "numpy", "cv2", "PIL", "faiss")
    sources = (
        Source(
            "mast3r_slam",
            "rmurai0610/MASt3R-SLAM",
            "b0ae540fa52c236b850af53f6445513d8f4d927c",
            sha256="cb5807279d737d30cad0aab6116f731fefca9b3bc3e5649cdd75b9ada555bc59",
            tree="21a1f53d6bdf32a42abaa200bbcda997e6857cb965549e68aad74301a3a32c4b",
            # the stored archive lacks the Eigen and pyimgui submodules (Debian's Eigen serves; the viewer is left
            # out), one EuRoC ground truth, a GIF and two viewer meshes (its .absent.txt)
            absent=(
                "groundtruths/euroc/MH_01_easy.txt",
                "media/teaser.gif",
                "thirdparty/eigen/",
                "thirdparty/in3d/resources/meshes/lucy.obj",
                "thirdparty/in3d/resources/meshes/mustard_bottle.ply",
                "thirdparty/in3d/thirdparty/pyimgui/",
            ),
        ),
        LIETORCH,
    )
    network = Weights(
        WEIGHTS_NAME,
        "MASt3R-SLAM's README (checkpoints/): https://download.europe.naverlabs.com/ComputerVision/MASt3R/ "
        f"{WEIGHTS_NAME}, {RETRIEVAL_NAME} and {CODEBOOK_NAME} (non-commercial, naver/mast3r's CHECKPOINTS_NOTICE)",
        standin=True,
        arg="MAST3R_MODEL",
        companions=(RETRIEVAL_NAME, CODEBOOK_NAME),
    )
    native_build = NativeMethod(
        label="MASt3R-SLAM",
        source="mast3r_slam",
        parts=(("lietorch", "thirdparty/lietorch"),),
        patches=IMAGE / "patches.py",
        setups=(
            ("thirdparty/lietorch", ("lietorch_backends",)),
            (".", ("mast3r_slam_backends",)),
            (f"{CROCO}/models/curope", ("curope",)),
            ("thirdparty/mast3r/asmk", ("asmk.hamming",)),
        ),
        import_path=("thirdparty/lietorch", ".", f"{CROCO}/models/curope", "thirdparty/mast3r/asmk"),
        weights_name=WEIGHTS_NAME,
        standin=IMAGE / "standin_model.py",
        standin_args=(str(STANDIN_SEED),),
        standin_note=f"random init, torch seed {STANDIN_SEED}, {{out}}",
    )
    profile = Profile.rectified
    Params = Mast3rSlamParams
    process = f"{__name__}.process"  # its folder's process.py (`python -m`), given these params as one JSON object
    image_build = IMAGE_BUILD
    weights_name = WEIGHTS_NAME

    def frames_given(self, n: int):
        """Every `subsample`-th frame from the first (its dataset's rgb_files[::subsample]): coverage is of them."""
        return np.arange(0, n, self.params.subsample)
