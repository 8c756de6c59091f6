"""The DROID-SLAM process: `python -m slamrun.methods.droid_slam.process --build DIR --weights FILE --images ...
--out ... [--settings JSON]`.

`--settings` is slamrun's parameters of DROID-SLAM as one JSON object (the method's params, `json.dumps`ed: each
parameter is written once, in slamrun/methods/droid_slam/__init__.py's DroidSlamParams): demo.py's options by their
names (`filter_thresh` is --filter_thresh), DROID's `motion_damping`, and this runner's `seed`. A name this process
does not know (an image older than the runner) or a value of another type is bad input, named.

Tracks every `stride`-th frame of the view in order (3-channel, resized to about 384x512 pixels and cropped to a
multiple of 8, the intrinsics scaled, as DROID-SLAM's demo.py does) with the view's pinhole intrinsics, then calls
DROID's terminate() with EVERY frame of the view: after its two global bundle adjustments, its trajectory filler gives
each frame a pose (interpolated between the keyframes around it, then refined by motion-only bundle adjustment), and
terminate() returns them inverted, camera-to-world, as lietorch's [tx ty tz qx qy qz qw]. They are written as TUM at
the frames' view timestamps. Frames are numbered by their index in the view, so the filler interpolates on the view's
own frame axis. DROID-SLAM is imported from `--build` (its patched tree, with lietorch in thirdparty/lietorch and the
compiled extensions beside them).

Exit codes: 0 a trajectory was written, 1 bad input, 2 DROID-SLAM never initialised, 3 no CUDA device, 4 the keyframe
buffer is full.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from slamrun.methods.gpu_process import cuda_torch, frames, intrinsics, settings_over, weights_note, write_tum

# demo.py's options and defaults (the ones slamrun's parameters set; tests compare them with demo.py)
DEMO = {
    "stride": 3,
    "buffer": 512,
    "beta": 0.3,
    "filter_thresh": 2.4,
    "warmup": 8,
    "keyframe_thresh": 4.0,
    "frontend_thresh": 16.0,
    "frontend_window": 25,
    "frontend_radius": 2,
    "frontend_nms": 1,
    "backend_thresh": 22.0,
    "backend_radius": 2,
    "backend_nms": 3,
}
SETTINGS = DEMO | {"upsample": False, "motion_damping": 0.0, "seed": None}  # every setting, with its default
AREA = 384 * 512  # demo.py resizes every image to about this many pixels
FILL_BATCH = 16  # the trajectory filler's batch: it needs this many free slots in the keyframe buffer


def parse(argv: list[str] | None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog="droid_slam")
    for name in ("--build", "--weights", "--images", "--times", "--camera", "--out"):
        ap.add_argument(name, type=Path, required=True)
    ap.add_argument("--settings", default="{}", help="slamrun's parameters as one JSON object (see the module's text)")
    return ap.parse_args(argv)


def settings(text: str) -> dict:
    """Every setting (SETTINGS' defaults, the given ones over them) from `--settings`; a ValueError names what is
    wrong."""
    return settings_over(text, SETTINGS, ("stride", "buffer", "warmup"))


def droid_args(values: dict, weights: Path, image_size: tuple[int, int]) -> SimpleNamespace:
    """The `args` DROID's classes read (demo.py's namespace): headless, monocular, synchronous, on the one GPU."""
    return SimpleNamespace(
        **{name: value for name, value in values.items() if name not in ("stride", "seed")},
        weights=str(weights),
        image_size=list(image_size),
        disable_vis=True,
        stereo=False,
        asynchronous=False,
        frontend_device="cuda",
        backend_device="cuda",
    )


def resized(height: int, width: int) -> tuple[int, int, int, int]:
    """demo.py's image size: (h1, w1) of about AREA pixels with the aspect ratio kept, and the cropped (h, w), each a
    multiple of 8."""
    scale = np.sqrt(AREA / (height * width))
    h1, w1 = int(height * scale), int(width * scale)
    return h1, w1, h1 - h1 % 8, w1 - w1 % 8


def scaled_intrinsics(k: np.ndarray, height: int, width: int) -> np.ndarray:
    """fx fy cx cy for the resized image (demo.py: x terms by w1/w0, y terms by h1/h0; the crop keeps the origin)."""
    h1, w1, _, _ = resized(height, width)
    return np.array([k[0] * w1 / width, k[1] * h1 / height, k[2] * w1 / width, k[3] * h1 / height], dtype=np.float64)


def search_path(build: Path) -> list[str]:
    """Where DROID's flat modules, lietorch and the extensions are: the build's tree (build.json's `tree`)."""
    try:
        tree = build / json.loads((build / "build.json").read_text())["tree"]
    except (OSError, ValueError, KeyError, TypeError):
        tree = build
    return [str(tree / "thirdparty" / "lietorch"), str(tree / "droid_slam"), str(tree)]


class BadFrame(Exception):
    pass


def stream(paths: list[Path], indices, k: np.ndarray, height: int, width: int):
    """(frame index, uint8 image [1, 3, h, w], intrinsics [4]) for each index, read and resized as demo.py does."""
    import cv2
    import torch

    h1, w1, h, w = resized(height, width)
    intr = torch.as_tensor(scaled_intrinsics(k, height, width))
    for i in indices:
        image = cv2.imread(str(paths[i]), cv2.IMREAD_COLOR)
        if image is None:
            raise BadFrame(f"{paths[i]}: not a readable image")
        if image.shape[:2] != (height, width):
            raise BadFrame(f"{paths[i]}: {image.shape[1]}x{image.shape[0]}, the camera says {width}x{height}")
        image = cv2.resize(image, (w1, h1))[:h, :w]
        yield i, torch.as_tensor(image).permute(2, 0, 1)[None], intr


def run(argv: list[str] | None = None) -> int:
    args = parse(argv)
    try:
        values = settings(args.settings)
        paths, times = frames(args.images, args.times, 1)
        k, width, height = intrinsics(args.camera)
    except (OSError, ValueError, KeyError) as exc:
        print(f"droid_slam: {exc}", file=sys.stderr)
        return 1
    if not paths:
        print(f"droid_slam: {args.images}: no frames", file=sys.stderr)
        return 1
    sys.path[:0] = search_path(args.build)
    torch = cuda_torch("droid_slam", "DROID-SLAM", args.weights, values["seed"])
    if isinstance(torch, int):
        return torch
    from droid import Droid  # DROID's modules: lietorch, droid_backends

    _, _, h, w = resized(height, width)
    cfg = droid_args(values, args.weights, (h, w))
    tracked = range(0, len(paths), values["stride"])
    print(
        f"droid_slam: {len(tracked)} of {len(paths)} frames tracked (stride {values['stride']}), {width}x{height} "
        f"resized to {w}x{h}, settings {vars(cfg)}",
        flush=True,
    )
    print(f"droid_slam: network {weights_note(args.build, args.weights)}", flush=True)
    t0 = time.perf_counter()
    try:
        droid = Droid(cfg)
        for i, image, intr in stream(paths, tracked, k, height, width):
            droid.track(i, image, intrinsics=intr)
        keyframes = droid.video.counter.value
        if not droid.frontend.is_initialized:
            print(f"NOT INITIALIZED: DROID-SLAM kept {keyframes} keyframe(s), it starts at {values['warmup']}")
            return 2
        if keyframes + FILL_BATCH > values["buffer"]:
            print(
                f"droid_slam: {keyframes} keyframes fill the buffer of {values['buffer']} (the trajectory filler needs "
                f"{FILL_BATCH} more): raise params.buffer",
                file=sys.stderr,
            )
            return 4
        poses = droid.terminate(stream(paths, range(len(paths)), k, height, width))  # camera-to-world
    except BadFrame as exc:
        print(f"droid_slam: {exc}", file=sys.stderr)
        return 1
    torch.cuda.synchronize()
    seconds = time.perf_counter() - t0
    poses = np.asarray(poses, dtype=np.float64)
    if poses.shape != (len(paths), 7):
        print(f"droid_slam: terminate() gave poses of shape {poses.shape}, expected ({len(paths)}, 7)", file=sys.stderr)
        return 1
    write_tum(args.out, times, poses)
    peak_mb = torch.cuda.max_memory_allocated() / 2**20
    print(
        f"droid_slam: {len(poses)} poses ({keyframes} keyframes) in {seconds:.2f} s "
        f"({len(tracked) / seconds:.1f} tracked fps); PyTorch's peak allocation {peak_mb:.0f} MB",
        flush=True,
    )
    return 0


if __name__ == "__main__":
    sys.exit(run())
