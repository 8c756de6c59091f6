"""CNN-DSO (muskie82/CNN-DSO @ 46562f0): DSO with MonoDepth depth priors through monodepth-cpp.

Everything as DSO plus `cnn=MODEL` (model_city2kitti.pb, the frozen MonoDepth graph given to the image
build, or an untrained stand-in for plumbing tests: the image's labels say which). MonoDepth runs on the
first frame and each new keyframe. The image links TensorFlow 2's C++ libraries from PyPI's tensorflow-cpu
wheel (the authors used TensorFlow 1.6 built with Bazel): CPU inference only.
"""

from __future__ import annotations

from pathlib import Path

from pydantic import Field

from slamrun.datasets.view import PreparedView
from slamrun.methods.declare import Source
from slamrun.methods.dso_family import DsoFamily, DsoParams
from slamrun.methods.libraries import MONODEPTH
from slamrun.methods.upstream import GpuOptional, GpuOptionalParams


class CnnDsoParams(DsoParams, GpuOptionalParams):
    model: str = Field("/opt/CNN-DSO/model/model_city2kitti.pb", description="Frozen MonoDepth graph.")


class CnnDso(GpuOptional, DsoFamily):
    sources = (
        Source(
            "cnn_dso",
            "muskie82/CNN-DSO",
            "46562f00f5237279ecc5777769107058fd31e264",
            sha256="157813e5371566db4f872cfeafba2476f532e55e8dd35eab0ead7850b2b23776",
            tree="4924798bf7fad673fc27b2a9853419c8e7fdaa5c3ff4d1eea97e29c934259640",
        ),
    )
    network = MONODEPTH
    binary = "/opt/CNN-DSO/build/bin/dso_dataset"
    Params = CnnDsoParams

    def extra_args(self, view: PreparedView, workdir: Path) -> list[str]:
        return [f"cnn={self.params.model}"]

    def problems(self, backend: str) -> list[str]:
        gpu = ["cnn_dso's image runs TensorFlow on the CPU only (the tensorflow-cpu wheel): drop gpu: true"]
        return super().problems(backend) + (gpu if self.params.gpu else [])

    def environment(self) -> dict[str, str]:
        return self.cpu_environment()
