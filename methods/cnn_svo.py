"""CNN-SVO (yan99033/CNN-SVO @ d5591ea with monodepth-cpp), ROS, on the rectified view.

`vo_monodepth_online` (MonoDepth through TensorFlow C++, on the CPU unless `gpu: true`) reads
`<image_folder>/%06d.png` numbered from 0 and a ONE-column times file (the view's times_single.txt;
TUM-Mono's `id t exposure` would be read as ids). The image's wrapper `cnn-svo-run PARAMS` links the
view's frames under those names and runs it. It writes, at the end and keyframes only, into
$HOME/results/CNN_VO/ (HOME is the work directory): traj_estimate_ATE.txt (TUM) and traj_estimate.txt
(timestamp + 3x4 [R|t]). A run killed before the end writes nothing.
"""

from __future__ import annotations

from pathlib import Path

from pydantic import Field

from methods.base import read_tum_output
from methods.svo import Svo, SvoParams, ros_params_yaml
from methods.upstream import GpuOptional, GpuOptionalParams
from runner.datasets.views import PreparedView
from runner.errors import MethodFailure, TrajectoryFormatError
from runner.trajectory import Trajectory, read_timestamped_3x4


class CnnSvoParams(SvoParams, GpuOptionalParams):
    model: str = Field("/opt/CNN-SVO/model/model_city2kitti.pb", description="Frozen MonoDepth graph.")


class CnnSvo(GpuOptional, Svo):
    name = "cnn_svo"
    image = "slamrun/cnn_svo:latest"
    binary = "/opt/CNN-SVO/cnn-svo-run"
    Params = CnnSvoParams
    output_file = "results/CNN_VO/traj_estimate_ATE.txt"
    matrix_file = "results/CNN_VO/traj_estimate.txt"

    def parameters(self, view: PreparedView, workdir: Path) -> dict:
        values = super().parameters(view, workdir)
        values.update(
            {
                "svo/image_folder": str(workdir / "frames"),
                "svo/times_file": str(view.path(view.times_single)),
                "svo/monodepth_graph": self.params.model,
                "svo/frame_suffix": view.frame_suffix,
            }
        )
        return values

    def configure(self, view: PreparedView, workdir: Path) -> dict[str, str]:
        # The parent of the output folder must exist; the wrapper fills frames/ with %06d.png links.
        return {
            self.params_file: ros_params_yaml(self.parameters(view, workdir)),
            "results/CNN_VO/.keep": "",
            "frames/.keep": "",
        }

    def environment(self) -> dict[str, str]:
        return {**({"HOME": "/work"} if self.backend == "docker" else {}), **self.cpu_environment()}

    def read_trajectory(self, workdir: Path, view: PreparedView) -> Trajectory:
        try:
            return view.to_original(read_tum_output(workdir / self.output_file))
        except MethodFailure as first:
            if not (workdir / self.matrix_file).exists():
                raise first from None
        try:  # the 3x4 file when the TUM one is missing
            traj = read_timestamped_3x4(workdir / self.matrix_file)
        except TrajectoryFormatError as exc:
            raise MethodFailure("no_output", str(exc)) from None
        if len(traj) == 0:
            raise MethodFailure("not_initialized", "CNN-SVO wrote no pose")
        return view.to_original(traj)
