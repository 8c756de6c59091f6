"""What the GPU methods built by `slamrun native-build` (dpvo, droid_slam) share: slamrun's cache of native builds,
their build.json, the checks that a build can run here, and a Method base that takes its build and network from the
native build (`backend: local`) or from the image (`backend: docker|podman`)."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path
from typing import Any

from pydantic import Field

from slamrun.datasets.view import PreparedView
from slamrun.methods.base import Method, PythonProcess, trial_seed_param


def native_root() -> Path:
    """slamrun's cache of native builds ($XDG_CACHE_HOME/slamrun/native, default ~/.cache/slamrun/native)."""
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "slamrun" / "native"


def native_build_folder(name: str) -> Path:
    """Where `slamrun native-build NAME` puts method NAME's build by default: its own folder of the cache."""
    return native_root() / name


def read_build_record(build: Path) -> dict | None:
    """The build.json of a native build (what `slamrun native-build dpvo` wrote), or None when there is none."""
    try:
        record = json.loads((build / "build.json").read_text())
    except (OSError, ValueError):
        return None
    return record if isinstance(record, dict) else None


def installed_torch() -> str | None:
    """The version of PyTorch installed beside slamrun (read from its metadata: importing it takes seconds)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("torch")
    except PackageNotFoundError:
        return None


def native_problems(build: Path, weights: str | None, method: str, weights_name: str) -> list[str]:
    """Why a native build of `method` (DPVO, or another GPU method built by `slamrun native-build`) at `build` cannot
    run here ([] when it can)."""
    how = f"run `slamrun native-build {method}` (a PyTorch with CUDA and nvcc needed), or give params.build"
    record = read_build_record(build)
    if record is None:
        return [f"{method} has no native build at {build} (no build.json): {how}"]
    torch = installed_torch()
    if torch is None:
        return [f"{method} runs on PyTorch, which this Python ({sys.executable}) lacks: install it, then {how}"]
    if record.get("torch_dist") != torch:  # the distribution's version (torch.__version__ may add +cuXXX)
        return [
            f"{method}'s native build at {build} was made for PyTorch {record.get('torch_dist')}, this Python has "
            f"{torch}: rebuild it (`slamrun native-build {method}`)"
        ]
    if weights is not None:
        return [] if Path(weights).is_file() else [f"{method}: params.weights: {weights} not found"]
    if not (build / record.get("weights_file", f"weights/{weights_name}")).is_file():
        return [
            f"{method}'s native build at {build} holds no network: rebuild with --weights {weights_name}=FILE (or "
            f"--standin-model for plumbing tests), or give params.weights"
        ]
    return []


def weights_param(weights_name: str) -> Any:
    """The `weights` parameter of a method whose network is `weights_name` (NativeGpuMethod.weights reads it)."""
    return Field(
        None, description=f"The network ({weights_name}); default: the one the native build (or the image) holds."
    )


def build_param(name: str) -> Any:
    """The `build` parameter of method `name` (NativeGpuMethod.build_dir reads it)."""
    return Field(None, description=f"Folder of a native build (default: where `slamrun native-build {name}` puts it).")


def torch_seed_param() -> Any:
    """The `seed` parameter of a method whose randomness is PyTorch's (its seed_param)."""
    return trial_seed_param(
        "Seed of PyTorch's generators",
        "a fixed value makes every trial the same seed; the GPU's own order still varies",
    )


class NativeGpuMethod(PythonProcess, Method):
    """A GPU method run as slamrun's own Python process: natively from a build in slamrun's cache, or in its image."""

    needs_gpu = True
    native = True
    # its process says the machine lacks what it needs (gpu_process.cuda_torch: no CUDA device; MASt3R-SLAM's: too
    # little GPU memory): the run is not the method's failure
    infra_pattern = r"^(NO GPU|GPU MEMORY):"
    modules = ("torch", "numpy", "cv2")
    process: str  # its process's module (`python -m`), which reads the settings as one JSON object
    image_build: str  # where the image holds the build (its network in weights/)
    weights_name: str  # the network's file name (dpvo.pth, droid.pth)
    backend: str = "local"

    def default_build(self) -> Path:
        """Where slamrun's cache holds this method's native build: a folder named by the method."""
        return native_build_folder(self.name)

    def for_backend(self, backend: str) -> Method:
        method = super().for_backend(backend)
        method.backend = backend
        return method

    def build_dir(self) -> str:
        if self.backend != "local":
            return self.image_build
        return self.params.build or str(self.default_build())

    def weights(self) -> str:
        if self.params.weights:
            return self.params.weights
        if self.backend != "local":
            return f"{self.image_build}/weights/{self.weights_name}"
        record = read_build_record(Path(self.build_dir())) or {}
        return str(Path(self.build_dir()) / record.get("weights_file", f"weights/{self.weights_name}"))

    def build_record(self) -> dict | None:
        """The native build it runs on the local backend: its folder, and its build.json's source, patches, PyTorch,
        CUDA, targets and network (given, or a stand-in: plumbing only)."""
        if self.backend != "local" or (record := read_build_record(Path(self.build_dir()))) is None:
            return None
        keys = ("source", "parts", "patches", "torch", "cuda", "arch", "weights")
        return {"folder": self.build_dir(), **{k: record[k] for k in keys if k in record}}

    def settings(self) -> str:
        """Its parameters as one JSON object, as its process reads them (`--settings`): every one but where the build
        and the network are, by its name in the params model, the one place each is written."""
        return json.dumps(self.params.model_dump(exclude={"weights", "build"}), sort_keys=True)

    def command(self, view: PreparedView, workdir: Path) -> list[str]:
        return [
            self.python, "-m", self.process, "--build", self.build_dir(), "--weights", self.weights(),
            "--images", str(view.path(view.images_dir)), "--times", str(view.path(view.times)),
            "--camera", str(view.path("camera_pinhole.json")), "--out", str(workdir / self.output_file),
            "--settings", self.settings(),
        ]  # fmt: skip

    def problems(self, backend: str) -> list[str]:
        if backend != "local":
            if self.recipe().exists():
                return []  # a missing image is said by the backend, naming `slamrun images --method NAME`
            return [f"{self.name}'s image {self.image} has no recipe (no {self.recipe()}): use backend: local"]
        build = Path(self.params.build or self.default_build())
        return native_problems(build, self.params.weights, self.name, self.weights_name)
