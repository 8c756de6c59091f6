"""DSM (jzubizarreta/dsm @ 36ab5cf): direct sparse mapping with a persistent map, on the rectified view.

Upstream has only GUI examples that never save a trajectory; the image builds our headless driver
`dsm_headless CALIB SETTINGS IMAGES TIMES OUT` against libdsm: no visualiser, undistorted frames fed
with their timestamps, then every keyframe pose (camera-to-world 4x4) written as TUM. Calibration is
OpenCV radial-tangential in pixels (zero for the rectified view). Lost is permanent.
"""

from __future__ import annotations

from pathlib import Path

from pydantic import Field

from slamrun.datasets.view import PreparedView, Profile
from slamrun.methods.declare import Source
from slamrun.methods.upstream import UpstreamMethod, UpstreamParams, pinhole_of


class DsmParams(UpstreamParams):
    single_threaded: bool = Field(True, description="DSM's singleThreaded setting (its default).")
    num_active_points: int = Field(1500, ge=100, description="DSM's numActivePoints.")
    loop_closure: bool = Field(
        False, description="Map reuse through covisible keyframes (off: doOnlyTemporalOpt = true, as the study)."
    )


class Dsm(UpstreamMethod):
    sources = (
        Source(
            "dsm",
            "jzubizarreta/dsm",
            "36ab5cf20ba4f83fc30c48cb0106c85e98aa9008",
            sha256="1ec626b114e1a8bf649ddcc2f163195001403f0fca769100861f918784aee4a9",
            tree="b56e326732b091996fc6b7af820f528c881ee1fee98fa8c8f695c0b75591dd1b",
        ),
    )
    binary = "/opt/dsm/build/bin/dsm_headless"
    profile = Profile.rectified
    loop_closure_switch = "settings doOnlyTemporalOpt = true"
    Params = DsmParams
    output_file = "dsm_trajectory.txt"
    not_initialized_pattern = r"not initialized|initialization failed"
    lost_pattern = r"tracking lost|LOST"

    def configure(self, view: PreparedView, workdir: Path) -> dict[str, str]:
        fx, fy, cx, cy = pinhole_of(view)
        calib = (
            "%YAML:1.0\n---\n"
            'Camera.type: "PINHOLE"\n'
            f"Camera.fx: {fx:.10g}\nCamera.fy: {fy:.10g}\nCamera.cx: {cx:.10g}\nCamera.cy: {cy:.10g}\n"
            "Camera.k1: 0.0\nCamera.k2: 0.0\nCamera.p1: 0.0\nCamera.p2: 0.0\nCamera.k3: 0.0\n"
            f"Camera.width: {view.width}\nCamera.height: {view.height}\n"
        )
        p = self.params
        values = {  # DSM's `key = value` settings; unnamed keys keep DSM's defaults
            "singleThreaded": p.single_threaded,
            "doOnlyTemporalOpt": not p.loop_closure,
            "numActivePoints": p.num_active_points,
            "showDepthMap": False,
            "printSummary": True,
            "saveDepthMaps": False,
            "saveOptErrorDist": False,
        }
        settings = "".join(f"{k} = {str(v).lower() if isinstance(v, bool) else v}\n" for k, v in values.items())
        return {"calib.yaml": calib, "settings.txt": settings}

    def busy_threads(self) -> int:
        return 1 if self.params.single_threaded else 2  # singleThreaded (its default): one

    def command(self, view: PreparedView, workdir: Path) -> list[str]:
        return [
            self.exe(),
            str(workdir / "calib.yaml"),
            str(workdir / "settings.txt"),
            str(view.path(view.images_dir)),
            str(view.path(view.times)),
            str(workdir / self.output_file),
        ]
