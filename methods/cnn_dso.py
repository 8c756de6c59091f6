"""CNN-DSO (muskie82/CNN-DSO @ 46562f0): DSO with MonoDepth depth priors (TensorFlow C++ 1.6).

Everything as DSO plus `cnn=MODEL` (model_city2kitti.pb, a frozen MonoDepth graph fetched at image build
time). MonoDepth runs on the first frame and each new keyframe, on the CPU unless `gpu: true`.
"""

from __future__ import annotations

from pathlib import Path

from pydantic import Field

from methods.dso import Dso, DsoParams
from methods.upstream import GpuOptional, GpuOptionalParams
from runner.datasets.views import PreparedView


class CnnDsoParams(DsoParams, GpuOptionalParams):
    model: str = Field("/opt/CNN-DSO/model/model_city2kitti.pb", description="Frozen MonoDepth graph.")


class CnnDso(GpuOptional, Dso):
    name = "cnn_dso"
    image = "slamrun/cnn_dso:latest"
    binary = "/opt/CNN-DSO/build/bin/dso_dataset"
    Params = CnnDsoParams

    def extra_args(self, view: PreparedView, workdir: Path) -> list[str]:
        return [f"cnn={self.params.model}"]

    def environment(self) -> dict[str, str]:
        return self.cpu_environment()
