"""LSD-SLAM (tum-vision/lsd_slam @ d1e6f0e), ROS, on the native view (TUM-Mono camera.txt works as is).

The image's wrapper `lsd-slam-run LIST CALIB OUT` starts roscore and runs `rosrun lsd_slam_core dataset_slam
_files:=LIST _hz:=0 _calib:=CALIB` (sequential tracking and mapping) with our patch that writes every
keyframe's final pose with its frame index to OUT after finalize() (upstream writes no trajectory file)
and without the OpenCV debug windows. OUT rows: `frame_index tx ty tz qx qy qz qw`, camera-to-world.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from methods.upstream import UpstreamMethod, UpstreamParams
from runner.datasets.views import PreparedView, Profile
from runner.errors import MethodFailure
from runner.trajectory import Trajectory, from_arrays


class LsdSlam(UpstreamMethod):
    name = "lsd_slam"
    image = "slamrun/lsd_slam:latest"
    binary = "/opt/lsd_slam/lsd-slam-run"
    profile = Profile.native
    loop_closure_switch = "_doSLAM:=false"
    Params = UpstreamParams
    output_file = "lsd_poses.txt"
    list_file = "files.txt"
    lost_pattern = r"TRACKING LOST"

    def configure(self, view: PreparedView, workdir: Path) -> dict[str, str]:
        # the frame order: the view's images (increasing view time), one absolute path per line
        names = [f"{i:06d}{view.frame_suffix}" for i in range(view.n_frames)]
        return {self.list_file: "".join(f"{view.path(view.images_dir)}/{n}\n" for n in names)}

    def command(self, view: PreparedView, workdir: Path) -> list[str]:
        return [
            self.exe(),
            str(workdir / self.list_file),
            str(view.path(view.camera)),
            str(workdir / self.output_file),
            "1" if self.params.loop_closure else "0",
        ]

    def read_trajectory(self, workdir: Path, view: PreparedView) -> Trajectory:
        path = workdir / self.output_file
        if not path.exists():
            raise MethodFailure("no_output", f"LSD-SLAM wrote no {path.name}")
        rows = np.loadtxt(path, ndmin=2, comments="#")
        if rows.size == 0:
            raise MethodFailure("not_initialized", f"{path.name} holds no pose")
        if rows.shape[1] != 8:
            raise MethodFailure(
                "no_output", f"{path.name}: {rows.shape[1]} columns, expected 'index tx ty tz qx qy qz qw'"
            )
        index = rows[:, 0].astype(int)
        if index.min() < 0 or index.max() >= view.n_frames:
            raise MethodFailure("no_output", f"{path.name}: frame index {index.max()} outside 0..{view.n_frames - 1}")
        t_view = view.view_timestamps()[index]
        return view.to_original(from_arrays(t_view, rows[:, 1:4], rows[:, 4:8]))
