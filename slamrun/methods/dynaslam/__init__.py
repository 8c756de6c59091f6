"""DynaSLAM (BertaBescos/DynaSLAM @ 8f894a8): ORB-SLAM2 plus Mask R-CNN segmentation of dynamic objects.

`mono_tum VOCAB SETTINGS SEQDIR [MASKDIR]` must run from the repository root; the image's wrapper
`dynaslam-run` does that and copies KeyFrameTrajectory.txt into the work directory. Without masks it is
plain ORB-SLAM2. Mask R-CNN runs on the CPU: the image (Debian 11, tensorflow-cpu 1.15 for Python 2.7) has no
GPU build, so `gpu: true` is refused rather than claimed. 640x480 is hard-coded upstream.
"""

from __future__ import annotations

from pathlib import Path

from pydantic import Field

from slamrun.datasets.view import PreparedView
from slamrun.errors import MethodFailure
from slamrun.methods.declare import Source, VerifyScope, Weights
from slamrun.methods.orb_slam2_family import ORB_VOCABULARY, OrbSlam2Family, OrbSlam2Params, orb_vocabulary


class DynaSlamParams(OrbSlam2Params):
    vocabulary: str = Field("/opt/DynaSLAM/Vocabulary/ORBvoc.txt", description="ORB vocabulary (ORBvoc.txt).")
    masks: bool = Field(True, description="Segment every frame with Mask R-CNN (off: plain ORB-SLAM2).")


class DynaSlam(OrbSlam2Family):
    sources = (
        Source(
            "dynaslam",
            "BertaBescos/DynaSLAM",
            "8f894a8b9d63c0a608fd871d63c10796491b9312",
            sha256="c99080b422cf68887f8fb98705b46279a899267a243f96bf35185d8c15ea7f34",
            tree="87c56f71a912a1152dfd44d3fbdef9d7171dccc94d8e90619da01c54281c00a9",
            absent=(ORB_VOCABULARY,),
        ),
    )
    vocabulary = orb_vocabulary("dynaslam")
    network = Weights(
        "mask_rcnn_coco.h5",
        "the matterport/Mask_RCNN GitHub release v2.0 (mask_rcnn_coco.h5)",
        standin=True,
        arg="MASK_RCNN_MODEL",
    )
    # Mask R-CNN (ResNet-101 at 1024x1024) segments every frame on the CPU: 6-10 s a frame on 2 cores alone (more
    # when other work shares them), so the default 2,400 frames would take 4-7 hours; this takes 20-35 minutes. The
    # whole loop in 100 frames moves 3 times as far per frame: ORB-SLAM2 paced in real time loses some of those runs,
    # at Mask R-CNN's pace (local mapping done between frames) it tracked them (checked with timestamps slowed 25
    # times). A run took 14 minutes while little else ran, and hit 900 s while image builds shared the cores: 2400 s.
    verify_scope = VerifyScope(("room_a",), 1, 100, "Mask R-CNN on the CPU, ~10 s a frame", timeout_s=2400.0)
    binary = "/opt/DynaSLAM/dynaslam-run"
    Params = DynaSlamParams
    loop_closure_switch = "env ORB_SLAM2_NO_LOOP=1 (patch in slamrun/methods/dynaslam/image)"

    def configure(self, view: PreparedView, workdir: Path) -> dict[str, str]:
        if (view.width, view.height) != (640, 480):
            raise MethodFailure(
                "crashed", f"DynaSLAM hard-codes 640x480 frames; the view is {view.width}x{view.height}"
            )
        return {**super().configure(view, workdir), "masks/.keep": ""}

    def command(self, view: PreparedView, workdir: Path) -> list[str]:
        argv = [self.exe(), self.params.vocabulary, str(workdir / self.settings_file), str(view.root)]
        if self.params.masks:
            argv.append(str(workdir / "masks"))
        return argv

    def environment(self) -> dict[str, str]:
        return {**super().environment(), "MPLBACKEND": "Agg", "SLAMRUN_WORKDIR": "/work", "CUDA_VISIBLE_DEVICES": ""}
