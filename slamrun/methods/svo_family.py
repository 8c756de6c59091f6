"""SVO's family (SVO, CNN-SVO): SVO's parameters (a flat rosparam file, `svo/` namespace) and the adapter of slamrun's
offline drivers (`svo_offline PARAMS`, `cnn_svo_offline PARAMS`: exit 3 when no pose was written). Each member's folder
declares its own name, image, sources and binary."""

from __future__ import annotations

from pathlib import Path
from typing import ClassVar

from pydantic import Field

from slamrun.datasets.view import PreparedView, Profile
from slamrun.methods.upstream import UpstreamMethod, UpstreamParams


class SvoParams(UpstreamParams):
    max_fts: int = Field(120, ge=10, description="svo/max_fts: features per frame.")
    grid_size: int = Field(30, ge=5, description="svo/grid_size in pixels.")
    n_pyr_levels: int = Field(3, ge=1, description="svo/n_pyr_levels.")
    max_n_kfs: int = Field(10, ge=0, description="svo/max_n_kfs kept in the map (0: unlimited).")
    init_min_disparity: float = Field(
        10.0,
        gt=0,
        description="svo/init_min_disparity in pixels (SVO: 50): median KLT disparity before the homography "
        "initialisation; lower suits non-planar scenes (see the module's documentation).",
    )


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


class SvoFamily(UpstreamMethod):
    """The adapter SVO's family shares: its parameter file, command line, output and failure patterns."""

    threads = 2  # the frame handler and its depth-filter thread
    profile = Profile.native
    loop_closure_switch = None  # SVO has no loop closure
    Params = SvoParams
    output_file = "traj_estimate.txt"
    params_file = "svo_params.yaml"
    no_pose_exit: ClassVar[int] = 3  # the drivers' exit status when they wrote no pose
    not_initialized_pattern = r"^slamrun: never initiali[sz]ed"
    lost_pattern = r"^slamrun: tracking lost"

    def parameters(self, view: PreparedView, workdir: Path) -> dict:
        return {
            "svo/dataset_directory": str(view.root),
            "svo/output_file": str(workdir / self.output_file),
            "svo/trace_dir": str(workdir),
            "svo/trace_name": "svo",
            "svo/cam_model": "ATAN",
            "svo/camera_file": str(view.path(view.camera)),
            **self.svo_parameters(),
        }

    def svo_parameters(self) -> dict:
        """SVO's own parameters (Config), from the method's params."""
        p = self.params
        return {
            "svo/max_fts": p.max_fts,
            "svo/grid_size": p.grid_size,
            "svo/n_pyr_levels": p.n_pyr_levels,
            "svo/max_n_kfs": p.max_n_kfs,
            "svo/init_min_disparity": p.init_min_disparity,
            "svo/use_imu": False,
        }

    def configure(self, view: PreparedView, workdir: Path) -> dict[str, str]:
        return {self.params_file: ros_params_yaml(self.parameters(view, workdir))}

    def command(self, view: PreparedView, workdir: Path) -> list[str]:
        return [self.exe(), str(workdir / self.params_file)]

    def accepts_exit(self, exit_code: int, workdir: Path) -> bool:
        # exit 3: the run ended normally without a pose; read_trajectory then says not_initialized
        return exit_code in (0, self.no_pose_exit)
