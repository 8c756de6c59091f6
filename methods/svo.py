"""SVO (uzh-rpg/rpg_svo @ d616106 with rpg_vikit, fast, Sophus @ a621ff), ROS, on the rectified view.

The offline `svo_ros benchmark` node reads images.txt (`timestamp name`) from svo/dataset_directory and
writes <trace_dir>/traj_estimate.txt (TUM, camera-to-world, every tracked frame). The image's wrapper
`svo-run PARAMS` starts roscore, loads the parameter file and runs it; our patch restarts the
initialisation when it stalls (upstream stays paused forever). Its parameters are tuned for 752x480,
so the 640x480 rectified view is the safer input.
"""

from __future__ import annotations

from pathlib import Path

from pydantic import Field

from methods.upstream import UpstreamMethod, UpstreamParams, pinhole_of
from runner.datasets.views import PreparedView, Profile


class SvoParams(UpstreamParams):
    max_fts: int = Field(120, ge=10, description="svo/max_fts: features per frame.")
    grid_size: int = Field(30, ge=5, description="svo/grid_size in pixels.")
    n_pyr_levels: int = Field(3, ge=1, description="svo/n_pyr_levels.")
    max_n_kfs: int = Field(10, ge=2, description="svo/max_n_kfs kept in the map.")


def ros_params_yaml(values: dict) -> str:
    """A flat rosparam YAML file (namespace `svo/`)."""
    out = []
    for k, v in values.items():
        if isinstance(v, bool):
            v = "true" if v else "false"
        elif isinstance(v, str):
            v = f'"{v}"'
        out.append(f"{k}: {v}")
    return "\n".join(out) + "\n"


class Svo(UpstreamMethod):
    name = "svo"
    image = "slamrun/svo:latest"
    binary = "/opt/svo/svo-run"
    profile = Profile.rectified
    loop_closure_switch = None  # SVO has no loop closure
    Params = SvoParams
    output_file = "traj_estimate.txt"
    params_file = "svo_params.yaml"
    not_initialized_pattern = r"Init: .*(failed|FAILURE)|no keyframe initialised"
    lost_pattern = r"Relocalization failed|tracking lost"

    def parameters(self, view: PreparedView, workdir: Path) -> dict:
        fx, fy, cx, cy = pinhole_of(view)
        p = self.params
        return {
            "svo/dataset_directory": str(view.root),
            "svo/dataset_first_frame": 0,
            "svo/trace_dir": str(workdir),
            "svo/trace_name": "svo",
            "svo/cam_model": "Pinhole",
            "svo/cam_width": view.width,
            "svo/cam_height": view.height,
            "svo/cam_fx": fx,
            "svo/cam_fy": fy,
            "svo/cam_cx": cx,
            "svo/cam_cy": cy,
            "svo/cam_d0": 0.0,
            "svo/cam_d1": 0.0,
            "svo/cam_d2": 0.0,
            "svo/cam_d3": 0.0,
            "svo/max_fts": p.max_fts,
            "svo/grid_size": p.grid_size,
            "svo/n_pyr_levels": p.n_pyr_levels,
            "svo/max_n_kfs": p.max_n_kfs,
            "svo/use_imu": False,
        }

    def configure(self, view: PreparedView, workdir: Path) -> dict[str, str]:
        return {self.params_file: ros_params_yaml(self.parameters(view, workdir))}

    def command(self, view: PreparedView, workdir: Path) -> list[str]:
        return [self.exe(), str(workdir / self.params_file)]
