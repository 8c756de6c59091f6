"""The DPVO process: `python -m slamrun.methods.dpvo.process --build DIR --weights FILE --images ... --out ...
[--settings JSON]`.

`--settings` is slamrun's parameters of DPVO as one JSON object (the method's params, `json.dumps`ed: each parameter
is written once, in slamrun/methods/dpvo/__init__.py's DpvoParams): `stride` and `seed` are this runner's, every other
name is a DPVO setting by its config.py name in lower case (`patches_per_frame` is PATCHES_PER_FRAME). A name this
process does not know (an image older than the runner) or a value of another type is bad input, named.

Feeds the view's frames (every `stride`-th, in order, 3-channel as demo.py reads them, cropped to a multiple of 16
pixels) to DPVO with the view's pinhole intrinsics, then writes every fed frame's pose (DPVO's `terminate()`: the
keyframes' poses and the dropped frames' poses from their keyframe's) as TUM, camera-to-world, at the frames' view
timestamps. DPVO is imported from `--build` (a native build: the patched tree with its compiled extensions).

Exit codes: 0 a trajectory was written, 1 bad input, 2 DPVO never initialised, 3 no CUDA device.
"""

from __future__ import annotations

import argparse
import json
import queue
import sys
import threading
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from slamrun.methods.gpu_process import cuda_torch, frames, intrinsics, settings_over, weights_note, write_tum

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
LOOP_CLOSURE_MODULES = ("numba", "pypose", "einops", "scipy")  # what DPV-SLAM's loop closure imports (optim_utils.py)
RUNNER = {"stride": 2, "seed": None}  # this runner's settings: demo.py's --stride; PyTorch's generators unseeded
PREFETCH = 8  # frames read ahead by a reader thread, as demo.py's reader process does


def parse(argv: list[str] | None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog="dpvo")
    for name in ("--build", "--weights", "--images", "--times", "--camera", "--out"):
        ap.add_argument(name, type=Path, required=True)
    ap.add_argument("--settings", default="{}", help="slamrun's parameters as one JSON object (see the module's text)")
    return ap.parse_args(argv)


def config(settings: str) -> tuple[dict, SimpleNamespace]:
    """This runner's settings (stride, seed) and DPVO's cfg (config.py's defaults, the given settings over them), from
    `--settings`; a ValueError names what is wrong."""
    values = settings_over(settings, RUNNER | {key.lower(): value for key, value in CONFIG.items()}, ("stride",))
    runner = {name: values.pop(name) for name in RUNNER}
    return runner, SimpleNamespace(**{name.upper(): value for name, value in values.items()})


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


def missing_for_loop_closure() -> list[str]:
    """The modules DPV-SLAM's loop closure imports that this environment lacks (an image built before it had them)."""
    import importlib.util

    return [name for name in LOOP_CLOSURE_MODULES if importlib.util.find_spec(name) is None]


def run(argv: list[str] | None = None) -> int:
    args = parse(argv)
    try:
        runner, cfg = config(args.settings)
        paths, times = frames(args.images, args.times, runner["stride"])
        k, width, height = intrinsics(args.camera)
    except (OSError, ValueError, KeyError) as exc:
        print(f"dpvo: {exc}", file=sys.stderr)
        return 1
    if cfg.LOOP_CLOSURE and (missing := missing_for_loop_closure()):
        print(
            f"dpvo: loop_closure (DPV-SLAM) needs {', '.join(missing)}, which this environment lacks (an image built "
            "before slamrun installed them: build it again with `slamrun images --method dpvo`)",
            file=sys.stderr,
        )
        return 1
    sys.path.insert(0, str(import_root(args.build)))
    torch = cuda_torch("dpvo", "DPVO", args.weights, runner["seed"])
    if isinstance(torch, int):
        return torch
    from dpvo.dpvo import DPVO  # DPVO's CUDA code: builds a CUDA tensor at import

    print(
        f"dpvo: {len(paths)} frames (stride {runner['stride']}) of {width}x{height}, settings {vars(cfg)}", flush=True
    )
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
