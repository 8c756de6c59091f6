"""ORB-SLAM2 (raulmur/ORB_SLAM2 @ f2e6f51), monocular, on rectified frames.

`mono_tum VOCAB SETTINGS SEQDIR` reads SEQDIR/rgb.txt and writes KeyFrameTrajectory.txt (TUM, keyframes,
camera-to-world) in its working directory. The image's patch adds a loop-closure switch (the environment
variable ORB_SLAM2_NO_LOOP=1) and turns the viewer off.
"""

from __future__ import annotations

from pathlib import Path

from pydantic import Field

from slamrun.datasets.view import PreparedView, Profile
from slamrun.methods.base import folder_name, image_tag
from slamrun.methods.declare import Source, Vocabulary
from slamrun.methods.upstream import UpstreamMethod, UpstreamParams, fps_of, pinhole_of


class OrbSlam2Params(UpstreamParams):
    vocabulary: str = Field("/opt/ORB_SLAM2/Vocabulary/ORBvoc.txt", description="ORB vocabulary (ORBvoc.txt).")
    n_features: int = Field(2000, ge=100, description="ORBextractor.nFeatures (TUM-Mono: 2000).")
    scale_factor: float = Field(1.2, gt=1.0, description="ORBextractor.scaleFactor.")
    n_levels: int = Field(8, ge=1, description="ORBextractor.nLevels.")
    ini_th_fast: int = Field(20, ge=1, description="ORBextractor.iniThFAST.")
    min_th_fast: int = Field(7, ge=1, description="ORBextractor.minThFAST.")


def orb_settings_yaml(view: PreparedView, p: OrbSlam2Params, extra: dict | None = None) -> str:
    """ORB-SLAM2's OpenCV YAML settings for a rectified pinhole view (zero distortion)."""
    fx, fy, cx, cy = pinhole_of(view)
    values = {
        "Camera.fx": fx,
        "Camera.fy": fy,
        "Camera.cx": cx,
        "Camera.cy": cy,
        "Camera.k1": 0.0,
        "Camera.k2": 0.0,
        "Camera.p1": 0.0,
        "Camera.p2": 0.0,
        "Camera.k3": 0.0,
        "Camera.width": view.width,
        "Camera.height": view.height,
        "Camera.fps": round(fps_of(view), 3),
        "Camera.RGB": 0,
        "ORBextractor.nFeatures": p.n_features,
        "ORBextractor.scaleFactor": p.scale_factor,
        "ORBextractor.nLevels": p.n_levels,
        "ORBextractor.iniThFAST": p.ini_th_fast,
        "ORBextractor.minThFAST": p.min_th_fast,
        "Viewer.KeyFrameSize": 0.05,
        "Viewer.KeyFrameLineWidth": 1,
        "Viewer.GraphLineWidth": 0.9,
        "Viewer.PointSize": 2,
        "Viewer.CameraSize": 0.08,
        "Viewer.CameraLineWidth": 3,
        "Viewer.ViewpointX": 0,
        "Viewer.ViewpointY": -0.7,
        "Viewer.ViewpointZ": -1.8,
        "Viewer.ViewpointF": 500,
        **(extra or {}),
    }
    lines = ["%YAML:1.0", "---"]
    for k, v in values.items():
        lines.append(
            f"{k}: {float(v):.10g}"
            if isinstance(v, float) and not float(v).is_integer()
            else f"{k}: {v:.1f}"
            if isinstance(v, float)
            else f"{k}: {v}"
        )
    return "\n".join(lines) + "\n"


class OrbSlam2(UpstreamMethod):
    name = folder_name(__name__)  # its folder's
    image = image_tag(name)  # built from image/Dockerfile in its folder
    threads = 3  # tracking, local mapping and loop closing (ORB-SLAM2's three threads)
    sources = (
        Source(
            "orb_slam2",
            "raulmur/ORB_SLAM2",
            "f2e6f51cdc8d067655d90a78c06261378e07e8f3",
            sha256="9470620833e1e57aff2aec40a5e90a8c4f55f4bbb7da218dbe234210db320404",
            tree="de0da80496099c3ec5f1c14e9bc64382734ec86d1c6b20b7784d48612106e7f1",
            absent=("Vocabulary/ORBvoc.txt.tar.gz",),
        ),
    )
    vocabulary = Vocabulary("orb_slam2", "Vocabulary/ORBvoc.txt.tar.gz", "dbow2-text")
    binary = "/opt/ORB_SLAM2/Examples/Monocular/mono_tum"
    profile = Profile.rectified
    loop_closure_switch = "env ORB_SLAM2_NO_LOOP=1 (patch in slamrun/methods/orb_slam2/image)"
    Params = OrbSlam2Params
    output_file = "KeyFrameTrajectory.txt"
    settings_file = "settings.yaml"
    not_initialized_pattern = None  # an empty KeyFrameTrajectory.txt says it
    # a reset soon after initialisation is lost only when no new map follows (ORB-SLAM2 re-initialises)
    lost_pattern = r"Track lost soon after initialisation(?![\s\S]*New Map created)"

    def configure(self, view: PreparedView, workdir: Path) -> dict[str, str]:
        return {self.settings_file: orb_settings_yaml(view, self.params)}

    def command(self, view: PreparedView, workdir: Path) -> list[str]:
        return [self.exe(), self.params.vocabulary, str(workdir / self.settings_file), str(view.root)]

    def environment(self) -> dict[str, str]:
        return {} if self.params.loop_closure else {"ORB_SLAM2_NO_LOOP": "1"}
