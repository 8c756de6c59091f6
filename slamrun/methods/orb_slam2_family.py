"""ORB-SLAM2's family (ORB-SLAM2, DF-ORB-SLAM, DynaSLAM): ORB-SLAM2's parameters, its OpenCV YAML settings for a
rectified pinhole view, and the adapter of its `mono_tum VOCAB SETTINGS SEQDIR` command line (KeyFrameTrajectory.txt,
the loop-closure switch ORB_SLAM2_NO_LOOP=1 its members' images patch in). Each member's folder declares its own
name, image, sources, vocabulary and binary."""

from __future__ import annotations

from pathlib import Path

from pydantic import Field

from slamrun.datasets.view import PreparedView, Profile
from slamrun.methods.declare import Vocabulary
from slamrun.methods.upstream import UpstreamMethod, UpstreamParams, fps_of, pinhole_of

# Where the ORB-SLAM2 family's trees (and ORB-SLAM3's) keep the ORB vocabulary; the stored archives lack it
ORB_VOCABULARY = "Vocabulary/ORBvoc.txt.tar.gz"


# The viewer's settings, the same for ORB-SLAM2 and ORB-SLAM3 (whose images run without a viewer)
VIEWER = {
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
}


def orb_vocabulary(source: str) -> Vocabulary:
    """The ORB vocabulary (ORBvoc.txt, DBoW2 text) at ORB_VOCABULARY in the tree of source archive `source`."""
    return Vocabulary(source, ORB_VOCABULARY, "dbow2-text")


def pinhole_settings(view: PreparedView, camera: str) -> dict[str, float]:
    """A rectified view's pinhole intrinsics as ORB-SLAM's settings name them: `camera`.fx, .fy, .cx and .cy."""
    return dict(zip((f"{camera}.{k}" for k in ("fx", "fy", "cx", "cy")), pinhole_of(view), strict=True))


class OrbSlam2Params(UpstreamParams):  # its vocabulary and ORB extractor (ORB-SLAM3 keeps the extractor's settings)
    vocabulary: str = Field("/opt/ORB_SLAM2/Vocabulary/ORBvoc.txt", description="ORB vocabulary (ORBvoc.txt).")
    n_features: int = Field(2000, ge=100, description="ORBextractor.nFeatures (TUM-Mono: 2000).")
    scale_factor: float = Field(1.2, gt=1.0, description="ORBextractor.scaleFactor.")
    n_levels: int = Field(8, ge=1, description="ORBextractor.nLevels.")
    ini_th_fast: int = Field(20, ge=1, description="ORBextractor.iniThFAST.")
    min_th_fast: int = Field(7, ge=1, description="ORBextractor.minThFAST.")


def orb_settings_yaml(view: PreparedView, p: OrbSlam2Params, extra: dict | None = None) -> str:
    """ORB-SLAM2's OpenCV YAML settings for a rectified pinhole view (zero distortion)."""
    values = {
        **pinhole_settings(view, "Camera"),
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
        **VIEWER,
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


class OrbSlam2Family(UpstreamMethod):
    """The adapter ORB-SLAM2's family shares: its settings file, command line, output and failure patterns."""

    threads = 3  # tracking, local mapping and loop closing (ORB-SLAM2's three threads)
    profile = Profile.rectified
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
