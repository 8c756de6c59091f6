"""CNN-SVO (yan99033/CNN-SVO @ d5591ea with monodepth-cpp), without ROS, on the rectified view.

The image builds CNN-SVO's svo library (SVO with MonoDepth depth for new seeds, FrameHandlerOnline) and slamrun's
offline driver `cnn_svo_offline PARAMS` (slamrun/methods/cnn_svo/image/cnn_svo_offline.cpp) in place of the ROS node
vo_monodepth_online: the frames of `svo/image_folder` in name order (the view's images/), their timestamps from a
ONE-column file (`svo/times_file`: the view's times_single.txt; TUM-Mono's `id t exposure` would be read as ids),
MonoDepth on the CPU unless `gpu: true`, `svo/frame_delay_ms` between frames (the node sleeps 50 ms), and at the
end the map's keyframe poses as TUM in `svo/output_file` (traj_estimate_ATE.txt in the work directory). Its
parameters are the authors' param/vo_kitti.yaml; the camera is the view's pinhole (CNN-SVO is pinhole-only). Exit
status 3: no keyframe left to write. The ROS node's own layout ($HOME/results/CNN_VO/traj_estimate_ATE.txt, TUM,
and traj_estimate.txt, timestamp + 3x4 [R|t]), in which the study's files were written, is read too.
"""

from __future__ import annotations

from pathlib import Path

from pydantic import Field

from slamrun.core.trajectory import Trajectory, read_timestamped_3x4
from slamrun.datasets.view import PreparedView, Profile
from slamrun.errors import MethodFailure, TrajectoryFormatError
from slamrun.methods.base import read_tum_output
from slamrun.methods.declare import Source
from slamrun.methods.libraries import MONODEPTH
from slamrun.methods.svo_family import SvoFamily, SvoParams
from slamrun.methods.upstream import GpuOptional, GpuOptionalParams, pinhole_of

# the authors' rpg_svo/svo_ros/param/vo_kitti.yaml (the keys the params do not set)
VO_KITTI = {
    "svo/core_n_kfs": 5,
    "svo/core_n_kfs_df": 5,
    "svo/triang_min_corner_score": 30,
    "svo/reproj_thresh": 2.0,
    "svo/poseoptim_thresh": 2.0,
    "svo/quality_min_fts": 50,
    "svo/quality_max_drop_fts": 150,
    "svo/min_num_features_kf": 100,
    "svo/kfselect_mindist": 0.01,
    "svo/use_motion_model": True,
    "svo/loba_num_iter": 10,
    "svo/sparse_img_align_iter": 10,
    "svo/structureoptim_num_iter": 10,
    "svo/subpix_n_iter": 10,
    "svo/init_min_tracked": 120,
}


class CnnSvoParams(SvoParams, GpuOptionalParams):
    # vo_kitti.yaml's values of the parameters SVO's adapter exposes
    max_fts: int = Field(200, ge=10, description="svo/max_fts (vo_kitti: 200).")
    n_pyr_levels: int = Field(4, ge=1, description="svo/n_pyr_levels (vo_kitti: 4).")
    max_n_kfs: int = Field(0, ge=0, description="svo/max_n_kfs (vo_kitti: 0, unlimited).")
    init_min_disparity: float = Field(20.0, gt=0, description="svo/init_min_disparity (vo_kitti: 20).")
    model: str = Field("/opt/CNN-SVO/model/model_city2kitti.pb", description="Frozen MonoDepth graph.")
    frame_delay_ms: int = Field(50, ge=0, description="Sleep between frames (the ROS node sleeps 50 ms).")


class CnnSvo(GpuOptional, SvoFamily):
    threads = 2  # the frame handler and its depth-filter thread
    sources = (
        Source(
            "cnn_svo",
            "yan99033/CNN-SVO",
            "d5591ea88103f8d1b26e5296129bf3b3196a14f1",
            sha256="72af2e352f67a8fc6a2a5fd010ee1fa38e58456316a73be0e7c70d267191abb7",
            tree="d5bd421d9725dfe656f289c095bf4a0e754e9ebab5d8a3c1499b61eff1a42c91",
        ),
    )
    network = MONODEPTH
    binary = "/opt/CNN-SVO/rpg_svo/svo/bin/cnn_svo_offline"
    profile = Profile.rectified
    Params = CnnSvoParams
    output_file = "traj_estimate_ATE.txt"
    # the ROS node's layout ($HOME/results/CNN_VO/): the TUM file, then the 3x4 one
    ros_output_file = "results/CNN_VO/traj_estimate_ATE.txt"
    matrix_file = "results/CNN_VO/traj_estimate.txt"
    not_initialized_pattern = None
    lost_pattern = None

    def parameters(self, view: PreparedView, workdir: Path) -> dict:
        fx, fy, cx, cy = pinhole_of(view)
        p = self.params
        return {
            "svo/image_folder": str(view.path(view.images_dir)),
            "svo/times_file": str(view.path(view.times_single)),
            "svo/cnn_model": p.model,
            "svo/output_file": str(workdir / self.output_file),
            "svo/frame_delay_ms": p.frame_delay_ms,
            "svo/trace_dir": str(workdir),
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
            **self.svo_parameters(),
            **VO_KITTI,
        }

    def environment(self) -> dict[str, str]:
        return self.cpu_environment()

    def read_trajectory(self, workdir: Path, view: PreparedView) -> Trajectory:
        for name in (self.output_file, self.ros_output_file):
            if (workdir / name).exists():
                return view.to_original(read_tum_output(workdir / name))
        if not (workdir / self.matrix_file).exists():
            raise MethodFailure("no_output", f"CNN-SVO wrote no {self.output_file}")
        try:  # the 3x4 file when no TUM one was written
            traj = read_timestamped_3x4(workdir / self.matrix_file)
        except TrajectoryFormatError as exc:
            raise MethodFailure("no_output", str(exc)) from None
        if len(traj) == 0:
            raise MethodFailure("not_initialized", "CNN-SVO wrote no pose")
        return view.to_original(traj)
