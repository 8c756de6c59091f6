"""The DPVO process: `python -m slamrun.methods.dpvo.process --build DIR --weights FILE --images ... --out ...
[settings]`.

Feeds the view's frames (every `--stride`-th, in order, 3-channel as demo.py reads them, cropped to a multiple of 16
pixels) to DPVO with the view's pinhole intrinsics, then writes every fed frame's pose (DPVO's `terminate()`: the
keyframes' poses and the dropped frames' poses from their keyframe's) as TUM, camera-to-world, at the frames' view
timestamps. DPVO is imported from `--build` (a native build: the patched tree with its compiled extensions).

Exit codes: 0 a trajectory was written, 1 bad input, 2 DPVO never initialised, 3 no CUDA device.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import queue
import sys
import threading
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np

# dpvo/config.py's settings (yacs is not needed for them): the ones slamrun's parameters set are overridden
CONFIG = {
    "BUFFER_SIZE": 4096,
    "CENTROID_SEL_STRAT": "RANDOM",
    "PATCHES_PER_FRAME": 80,
    "REMOVAL_WINDOW": 20,
    "OPTIMIZATION_WINDOW": 12,
    "PATCH_LIFETIME": 12,
    "KEYFRAME_INDEX": 4,
    "KEYFRAME_THRESH": 12.5,
    "MOTION_MODEL": "DAMPED_LINEAR",
    "MOTION_DAMPING": 0.5,
    "MIXED_PRECISION": True,
    "LOOP_CLOSURE": False,
    "BACKEND_THRESH": 64.0,
    "MAX_EDGE_AGE": 1000,
    "GLOBAL_OPT_FREQ": 15,
    "CLASSIC_LOOP_CLOSURE": False,
    "LOOP_CLOSE_WINDOW_SIZE": 3,
    "LOOP_RETR_THRESH": 0.04,
}
SETTINGS = (  # command-line option -> DPVO's setting, type
    ("patches_per_frame", "PATCHES_PER_FRAME", int),
    ("removal_window", "REMOVAL_WINDOW", int),
    ("optimization_window", "OPTIMIZATION_WINDOW", int),
    ("patch_lifetime", "PATCH_LIFETIME", int),
    ("keyframe_thresh", "KEYFRAME_THRESH", float),
    ("keyframe_index", "KEYFRAME_INDEX", int),
    ("motion_model", "MOTION_MODEL", str),
    ("motion_damping", "MOTION_DAMPING", float),
    ("mixed_precision", "MIXED_PRECISION", lambda s: s == "1"),
    ("centroid_sel_strat", "CENTROID_SEL_STRAT", str),
    ("buffer_size", "BUFFER_SIZE", int),
)
PREFETCH = 8  # frames read ahead by a reader thread, as demo.py's reader process does


def parse(argv: list[str] | None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog="dpvo")
    for name in ("--build", "--weights", "--images", "--times", "--camera", "--out"):
        ap.add_argument(name, type=Path, required=True)
    ap.add_argument("--stride", type=int, default=2)
    ap.add_argument("--seed", type=int)
    for option, _, kind in SETTINGS:
        ap.add_argument("--" + option.replace("_", "-"), dest=option, type=str if kind not in (int, float) else kind)
    return ap.parse_args(argv)


def config(args: argparse.Namespace) -> SimpleNamespace:
    """DPVO's cfg: config.py's defaults, the given settings over them."""
    values = dict(CONFIG)
    for option, key, kind in SETTINGS:
        given = getattr(args, option)
        if given is not None:
            values[key] = kind(given)
    return SimpleNamespace(**values)


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


def read_ahead(paths: list[Path]) -> queue.Queue:
    """A queue of (index, BGR image cropped to a multiple of 16), then None; filled by a reader thread."""
    import cv2

    q: queue.Queue = queue.Queue(maxsize=PREFETCH)

    def reader() -> None:
        for i, path in enumerate(paths):
            image = cv2.imread(str(path), cv2.IMREAD_COLOR)
            if image is None:
                q.put((i, None))
                return
            h, w = image.shape[:2]
            q.put((i, image[: h - h % 16, : w - w % 16]))
        q.put(None)

    threading.Thread(target=reader, daemon=True, name="frames").start()
    return q


def import_root(build: Path) -> Path:
    """Where DPVO's package and its extensions are: a native build's tree (its build.json's `tree`), else `build`."""
    try:
        return build / json.loads((build / "build.json").read_text())["tree"]
    except (OSError, ValueError, KeyError, TypeError):
        return build


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
    """`t tx ty tz qx qy qz qw` rows (DPVO's poses are x y z qx qy qz qw already)."""
    data = np.column_stack([timestamps, poses[:, :7]])
    np.savetxt(path, data, fmt="%.17g", header="timestamp tx ty tz qx qy qz qw")


def run(argv: list[str] | None = None) -> int:
    args = parse(argv)
    try:
        paths, times = frames(args.images, args.times, args.stride)
        k, width, height = intrinsics(args.camera)
    except (OSError, ValueError, KeyError) as exc:
        print(f"dpvo: {exc}", file=sys.stderr)
        return 1
    if not args.weights.is_file():
        print(f"dpvo: weights {args.weights} not found", file=sys.stderr)
        return 1
    sys.path.insert(0, str(import_root(args.build)))
    try:
        import torch
    except ImportError as exc:
        print(f"dpvo: PyTorch cannot be imported in {sys.executable} ({exc})", file=sys.stderr)
        return 1
    if not torch.cuda.is_available():
        print("NO GPU: DPVO runs on CUDA only and torch.cuda.is_available() is False", file=sys.stderr)
        return 3
    if args.seed is not None:
        torch.manual_seed(args.seed)
    from dpvo.dpvo import DPVO  # DPVO's CUDA code: builds a CUDA tensor at import

    cfg = config(args)
    print(f"dpvo: {len(paths)} frames (stride {args.stride}) of {width}x{height}, settings {vars(cfg)}", flush=True)
    print(f"dpvo: network {weights_note(args.build, args.weights)}", flush=True)
    slam = None
    intr = torch.from_numpy(k).cuda()
    t0 = time.perf_counter()
    t1 = None  # after the first frame: the network loaded and the first kernels warm
    with torch.no_grad():
        for item in iter(read_ahead(paths).get, None):
            i, image = item
            if image is None:
                print(f"dpvo: {paths[i]}: not a readable image", file=sys.stderr)
                return 1
            tensor = torch.from_numpy(image).permute(2, 0, 1).cuda()
            if slam is None:
                slam = DPVO(cfg, str(args.weights), ht=tensor.shape[1], wd=tensor.shape[2])
            slam(i, tensor, intr)
            if t1 is None:
                torch.cuda.synchronize()
                t1 = time.perf_counter()
        if slam is None or not slam.is_initialized:
            print(f"NOT INITIALIZED: DPVO took {0 if slam is None else slam.n} keyframe(s), it starts at 8")
            return 2
        n_keyframes = slam.n
        poses, tstamps = slam.terminate()
    torch.cuda.synchronize()
    t2 = time.perf_counter()
    seconds = t2 - t0
    steady = f"; {(len(paths) - 1) / (t2 - t1):.1f} fps after the first frame" if len(paths) > 1 and t2 > t1 else ""
    index = np.asarray(tstamps, dtype=np.int64)
    write_tum(args.out, times[index], np.asarray(poses, dtype=np.float64))
    peak_mb = torch.cuda.max_memory_allocated() / 2**20
    print(
        f"dpvo: {len(index)} poses ({n_keyframes} keyframes) in {seconds:.2f} s "
        f"({len(paths) / seconds:.1f} fps{steady}); "
        f"PyTorch's peak allocation {peak_mb:.0f} MB",
        flush=True,
    )
    return 0


if __name__ == "__main__":
    sys.exit(run())
