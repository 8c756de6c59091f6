"""What the GPU methods' own processes (DPVO's, DROID-SLAM's) share: their settings read over their defaults, the
view's frames and pinhole intrinsics, PyTorch on CUDA (or why not), the network's note, the TUM output. The standard
library and NumPy only (PyTorch imported when asked for): each image copies this module beside its process (its
Dockerfile: COPY methods/gpu_process.py)."""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

import numpy as np


def checked(name: str, value, default):
    """`value` for a setting whose default is `default`: of its type (an integer where a number is meant), else a
    ValueError naming it."""
    if default is None or type(value) is type(default) or (type(default) is float and type(value) is int):
        return value
    raise ValueError(f"setting {name}: {value!r} is not a {type(default).__name__} (default {default!r})")


def settings_over(text: str, defaults: dict, positive: tuple[str, ...]) -> dict:
    """The settings `--settings` gives over their `defaults`: a JSON object of known names, each value of its
    default's type, those named in `positive` at least 1; else a ValueError naming what is wrong."""
    given = json.loads(text)
    if not isinstance(given, dict):
        raise ValueError(f"--settings: a JSON object expected, got {text!r}")
    unknown = [name for name in given if name not in defaults]
    if unknown:
        raise ValueError(
            f"unknown setting {unknown[0]!r} (this process knows {', '.join(defaults)}): is the image older than "
            "slamrun?"
        )
    values = defaults | {name: checked(name, value, defaults[name]) for name, value in given.items()}
    for name in positive:
        if values[name] < 1:
            raise ValueError(f"setting {name}: {values[name]!r} is not a positive integer")
    return values


def frames(images: Path, times_file: Path, stride: int) -> tuple[list[Path], np.ndarray]:
    """The view's frames in order (every `stride`-th, the last always included) and their view timestamps."""
    times = np.loadtxt(times_file, ndmin=2)[:, 1]
    paths = sorted(p for p in images.iterdir() if p.suffix.lower() in (".png", ".pgm", ".jpg", ".jpeg"))
    if len(paths) != len(times):
        raise ValueError(f"{images}: {len(paths)} frames but {len(times)} timestamps in {times_file}")
    chosen = list(range(0, len(paths), stride))
    if chosen and chosen[-1] != len(paths) - 1:
        chosen.append(len(paths) - 1)
    return [paths[i] for i in chosen], times[chosen]


def intrinsics(camera: Path) -> tuple[np.ndarray, int, int]:
    cam = json.loads(camera.read_text())
    return np.array([cam["fx"], cam["fy"], cam["cx"], cam["cy"]], dtype=np.float32), cam["width"], cam["height"]


def cuda_torch(name: str, title: str, weights: Path, seed: int | None):
    """PyTorch with a CUDA device, seeded where `seed` is given: the module, or the process's exit code with its line
    on stderr (1: the weights file or PyTorch missing; 3: no GPU, `NO GPU: <title> runs on CUDA only ...`)."""
    if not weights.is_file():
        print(f"{name}: weights {weights} not found", file=sys.stderr)
        return 1
    try:
        import torch
    except ImportError as exc:
        print(f"{name}: PyTorch cannot be imported in {sys.executable} ({exc})", file=sys.stderr)
        return 1
    if not torch.cuda.is_available():
        print(f"NO GPU: {title} runs on CUDA only and torch.cuda.is_available() is False", file=sys.stderr)
        return 3
    if seed is not None:
        torch.manual_seed(seed)
    return torch


def weights_note(build: Path, weights: Path) -> str:
    """What the network is: the native build's record of it when it is the build's, else its SHA-256."""
    try:
        record = json.loads((build / "build.json").read_text())
        if (build / record["weights_file"]).resolve() == weights.resolve():
            return record["weights"]
    except (OSError, ValueError, KeyError, TypeError):
        pass
    return f"{weights} sha256 {hashlib.sha256(weights.read_bytes()).hexdigest()}"


def write_tum(path: Path, timestamps: np.ndarray, poses: np.ndarray) -> None:
    """`t tx ty tz qx qy qz qw` rows (DPVO's and DROID-SLAM's poses are x y z qx qy qz qw already)."""
    data = np.column_stack([timestamps, poses[:, :7]])
    np.savetxt(path, data, fmt="%.17g", header="timestamp tx ty tz qx qy qz qw")
