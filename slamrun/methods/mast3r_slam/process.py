"""The MASt3R-SLAM process: `python -m slamrun.methods.mast3r_slam.process --build DIR --weights FILE --images ...
--out ... [--settings JSON]`.

`--settings` is slamrun's parameters of MASt3R-SLAM as one JSON object (the method's params, `json.dumps`ed: each is
written once, in slamrun/methods/mast3r_slam/__init__.py's Mast3rSlamParams). A name this process does not know (an
image older than the runner) or a value of another type is bad input, named.

Runs MASt3R-SLAM as its main.py does with its evaluation configs (config/eval_calib.yaml, or eval_no_calib.yaml when
`calibrated` is false: single_thread, every `subsample`-th frame), the settings over them, headless: the view's frames
are its dataset (upstream's MonocularDataset, read, undistorted with the view's pinhole camera through its Intrinsics
and resized to 512 pixels as it does), the frontend loop is main.py's without the viewer, and the backend is main.py's
own run_backend, in a thread of this process instead of a second process (single_thread makes the frontend wait for
it after every new keyframe and relocalisation, so the order of their steps is main.py's; one process shares its
tensors without /dev/shm, so SharedKeyframes' share_memory_() is skipped and a plain lock and values stand in for the
multiprocessing Manager's; PyTorch's TF32 matmuls, which main.py turns on in its own process, are on for the
backend's thread too, where upstream's second process ran without them).

MASt3R-SLAM writes its keyframes only; this process also records, for every frame it tracked, its pose relative to
the keyframe it was tracked against (Sim(3), at tracking time), and writes at the end: each keyframe's optimised pose,
each tracked frame's keyframe pose times its relative pose, as SE(3) (upstream's as_SE3: the scale dropped, as its
save_traj writes keyframes) camera-to-world TUM at the frames' view timestamps. A frame skipped while relocalising
has no pose.

Before the network loads, the GPU memory it needs at the sequence's resolution (the network, the keyframe buffer,
a working margin) is checked against what the GPU has free: too little is `GPU MEMORY: ...`, exit 5.

Exit codes: 0 a trajectory was written, 1 bad input, 3 no CUDA device, 4 the keyframe buffer is full, 5 too little GPU
memory.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import threading
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from slamrun.methods.gpu_process import cuda_torch, frames, intrinsics, settings_over, weights_note, write_tum

SETTINGS = {
    "calibrated": True,
    "subsample": 2,
    "buffer": 512,
    "match_frac_thresh": 0.333,
    "min_match_frac": 0.05,
    "retrieval_k": 3,
    "retrieval_min_thresh": 5e-3,
    "seed": None,
}
# the retrieval head and its codebook, beside the network under the names its README's checkpoints/ gives them
# (main.py's backend loads checkpoints/<RETRIEVAL>; mast3r/retrieval/processor.py finds the codebook by that name)
RETRIEVAL = "MASt3R_ViTLarge_BaseDecoder_512_catmlpdpt_metric_retrieval_trainingfree.pth"
CODEBOOK = "MASt3R_ViTLarge_BaseDecoder_512_catmlpdpt_metric_retrieval_codebook.pkl"
# GPU memory: per keyframe of h x w pixels, SharedKeyframes' tensors on the GPU (img 3, X 3 and C 1 float32 per pixel;
# feat 1024 float32 and pos 2 int64 per 16x16 patch); the network's parameters as float32 (its checkpoint's size); and
# a working margin for the two-view inference, matching and the factor graph (an estimate, not measured on a GPU here)
FLOATS_PER_PIXEL = 3 + 3 + 1
PATCH_BYTES = 1024 * 4 + 2 * 8
WORKING_BYTES = 4 * 2**30


def parse(argv: list[str] | None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog="mast3r_slam")
    for name in ("--build", "--weights", "--images", "--times", "--camera", "--out"):
        ap.add_argument(name, type=Path, required=True)
    ap.add_argument("--settings", default="{}", help="slamrun's parameters as one JSON object (see the module's text)")
    args = ap.parse_args(argv)
    for name in ("build", "weights", "images", "times", "camera", "out"):  # the process changes its working folder
        setattr(args, name, getattr(args, name).absolute())
    return args


def settings(text: str) -> dict:
    """Every setting (SETTINGS' defaults, the given ones over them); a ValueError names what is wrong."""
    return settings_over(text, SETTINGS, ("subsample", "buffer", "retrieval_k"))


def companions(weights: Path) -> tuple[Path, Path]:
    """The retrieval head and its codebook beside the network, by the names MASt3R-SLAM's checkpoints/ gives them."""
    return weights.with_name(RETRIEVAL), weights.with_name(CODEBOOK)


def gpu_bytes_needed(height: int, width: int, buffer: int, network_bytes: int) -> int:
    """What MASt3R-SLAM holds on the GPU for frames of `height` x `width` (after its resize to 512): the keyframe
    buffer, the network and a working margin."""
    per_keyframe = height * width * FLOATS_PER_PIXEL * 4 + (height * width // 256) * PATCH_BYTES
    return buffer * per_keyframe + network_bytes + WORKING_BYTES


def config_file(tree: Path, calibrated: bool) -> Path:
    return tree / "config" / ("eval_calib.yaml" if calibrated else "eval_no_calib.yaml")


def search_path(build: Path) -> list[str]:
    """Where MASt3R-SLAM's modules, mast3r (with dust3r and croco), asmk and lietorch are: the build's tree."""
    try:
        tree = build / json.loads((build / "build.json").read_text())["tree"]
    except (OSError, ValueError, KeyError, TypeError):
        tree = build
    return [str(tree), str(tree / "thirdparty" / "mast3r"), str(tree / "thirdparty" / "mast3r" / "asmk"),
            str(tree / "thirdparty" / "lietorch")]  # fmt: skip


class Value:
    """A multiprocessing Manager's Value, in one process."""

    def __init__(self, _typecode: str, value):
        self.value = value


class LocalManager:
    """What SharedKeyframes and SharedStates take from a multiprocessing Manager, for threads of one process."""

    RLock = staticmethod(threading.RLock)
    Value = Value
    list = staticmethod(list)


@contextmanager
def unshared(torch):
    """Tensor.share_memory_() as a no-op: one process shares its tensors already, and a CPU tensor put in /dev/shm
    (1.2 GB of keyframe images) would not fit a container's 64 MB."""
    original = torch.Tensor.share_memory_
    torch.Tensor.share_memory_ = lambda self: self
    try:
        yield
    finally:
        torch.Tensor.share_memory_ = original


class Backend(threading.Thread):
    """main.py's run_backend in a thread; what it raised, if it did."""

    def __init__(self, target, args):
        super().__init__(daemon=True, name="mast3r-slam-backend")
        self.run_backend, self.args, self.error = target, args, None

    def run(self) -> None:
        try:
            self.run_backend(*self.args)
        except BaseException as exc:  # noqa: BLE001 - said by the frontend, which stops
            self.error = exc


class BackendDied(Exception):
    pass


class BufferFull(Exception):
    pass


def wait_for(backend: Backend, done) -> None:
    """main.py's single_thread waits: until `done()`, while the backend lives."""
    while not done():
        if not backend.is_alive():
            raise BackendDied(f"its backend stopped: {backend.error!r}")
        time.sleep(0.01)


def configured(tree: Path, values: dict) -> dict:
    """MASt3R-SLAM's global config from its evaluation config file, the settings over it (load_config reads the
    file it inherits relative to the working folder: the tree's)."""
    from mast3r_slam.config import config, load_config

    here = os.getcwd()
    os.chdir(tree)
    try:
        load_config(str(config_file(tree, values["calibrated"]).relative_to(tree)))
    finally:
        os.chdir(here)
    config["use_calib"] = values["calibrated"]
    config["single_thread"] = True
    config["dataset"]["subsample"] = values["subsample"]
    config["tracking"]["match_frac_thresh"] = values["match_frac_thresh"]
    config["tracking"]["min_match_frac"] = values["min_match_frac"]
    config["retrieval"]["k"] = values["retrieval_k"]
    config["retrieval"]["min_thresh"] = values["retrieval_min_thresh"]
    return config


class BadInput(Exception):
    pass


def read_inputs(args: argparse.Namespace) -> tuple[dict, list[Path], np.ndarray, np.ndarray, int, int]:
    """(settings, the view's frames, their timestamps, fx fy cx cy, width, height); BadInput names what is wrong."""
    try:
        values = settings(args.settings)
        paths, times = frames(args.images, args.times, 1)
        k, width, height = intrinsics(args.camera)
    except (OSError, ValueError, KeyError) as exc:
        raise BadInput(str(exc)) from None
    if not paths:
        raise BadInput(f"{args.images}: no frames")
    missing = [str(p) for p in companions(args.weights) if not p.is_file()]
    if missing and args.weights.is_file():
        raise BadInput(f"the network's retrieval files are not beside it: {', '.join(missing)}")
    return values, paths, times, k, width, height


def dataset_of(paths: list[Path], times: np.ndarray, k: np.ndarray, width: int, height: int, values: dict):
    """Upstream's MonocularDataset of the view's frames (every `subsample`-th), undistorted with the view's pinhole
    camera when calibrated; and its frames' size after the resize (h, w). BadInput for an unreadable first frame."""
    from mast3r_slam.dataloader import Intrinsics, MonocularDataset

    dataset = MonocularDataset()
    dataset.dataset_path = paths[0].parent
    dataset.rgb_files = [str(p) for p in paths]
    dataset.timestamps = times
    dataset.subsample(values["subsample"])
    try:
        h, w = dataset.get_img_shape()[0]
    except Exception as exc:  # noqa: BLE001 - cv2 and PIL say it their own ways
        raise BadInput(f"{paths[0]}: not a readable image ({exc})") from None
    if values["calibrated"]:
        dataset.use_calibration = True
        dataset.camera_intrinsics = Intrinsics.from_calib(dataset.img_size, width, height, [float(v) for v in k])
    return dataset, (int(h), int(w))


def memory_refusal(torch, shape: tuple[int, int], values: dict, weights: Path) -> tuple[str | None, str]:
    """(the `GPU MEMORY: ...` line when the GPU has too little free, else None; what is needed and free)."""
    (h, w), buffer = shape, values["buffer"]
    need = gpu_bytes_needed(h, w, buffer, weights.stat().st_size)
    free, total = torch.cuda.mem_get_info()
    said = f"about {need / 2**30:.1f} GiB of GPU memory needed, {free / 2**30:.1f} free"
    if need <= free:
        return None, said
    return (
        f"GPU MEMORY: MASt3R-SLAM needs about {need / 2**30:.1f} GiB at {w}x{h} with a buffer of {buffer} keyframes; "
        f"the GPU has {free / 2**30:.1f} GiB free of {total / 2**30:.1f} (a smaller params.buffer, or a GPU with "
        "more free memory)"
    ), said


def slam(torch, dataset, shape: tuple[int, int], values: dict, config: dict, weights: Path):
    """MASt3R-SLAM over the dataset: (its keyframes, each tracked frame's keyframe and relative pose). BackendDied or
    BufferFull stop it."""
    import lietorch
    from main import run_backend  # MASt3R-SLAM's main.py (its viewer imported only when it runs as a program)
    from mast3r_slam.frame import Mode, SharedKeyframes, SharedStates, create_frame
    from mast3r_slam.mast3r_utils import load_mast3r, mast3r_inference_mono
    from mast3r_slam.tracker import FrameTracker

    device = "cuda:0"
    with unshared(torch):
        manager = LocalManager()
        keyframes = SharedKeyframes(manager, *shape, buffer=values["buffer"])
        states = SharedStates(manager, *shape)
    model = load_mast3r(path=str(weights), device=device)
    K = None
    if values["calibrated"]:
        K = torch.from_numpy(dataset.camera_intrinsics.K_frame).to(device, dtype=torch.float32)
        keyframes.set_intrinsics(K)
    tracker = FrameTracker(model, keyframes, device)
    # main.py's backend loads the retrieval head itself (load_retriever's default path: checkpoints/ in the working
    # folder): it runs in a folder where checkpoints/ holds the files given
    backend = Backend(run_backend, (config, model, states, keyframes, K))
    relative: dict[int, tuple[int, object]] = {}  # frame -> (its keyframe, its pose relative to it: Sim(3) data)
    try:
        with retrieval_folder(weights):
            backend.start()
            frontend(dataset, model, tracker, keyframes, states, backend, relative, values["buffer"], device,
                     Mode, lietorch, create_frame, mast3r_inference_mono)  # fmt: skip
    finally:
        states.set_mode(Mode.TERMINATED)
    backend.join()
    return keyframes, relative


def run(argv: list[str] | None = None) -> int:
    args = parse(argv)
    try:
        values, paths, times, k, width, height = read_inputs(args)
    except BadInput as exc:
        print(f"mast3r_slam: {exc}", file=sys.stderr)
        return 1
    sys.path[:0] = search_path(args.build)
    torch = cuda_torch("mast3r_slam", "MASt3R-SLAM", args.weights, values["seed"])
    if isinstance(torch, int):
        return torch
    config = configured(Path(search_path(args.build)[0]), values)
    torch.backends.cuda.matmul.allow_tf32 = True  # as main.py
    torch.set_grad_enabled(False)
    try:
        dataset, shape = dataset_of(paths, times, k, width, height, values)
    except BadInput as exc:
        print(f"mast3r_slam: {exc}", file=sys.stderr)
        return 1
    refusal, memory = memory_refusal(torch, shape, values, args.weights)
    if refusal:
        print(refusal, file=sys.stderr)
        return 5
    print(
        f"mast3r_slam: {len(dataset)} of {len(paths)} frames (subsample {values['subsample']}), {width}x{height} "
        f"resized to {shape[1]}x{shape[0]}, {'calibrated' if values['calibrated'] else 'uncalibrated'}; {memory}; "
        f"settings {json.dumps(values)}",
        flush=True,
    )
    print(f"mast3r_slam: network {weights_note(args.build, args.weights)}", flush=True)
    t0 = time.perf_counter()
    try:
        keyframes, relative = slam(torch, dataset, shape, values, config, args.weights)
    except (BackendDied, BufferFull) as exc:
        print(f"mast3r_slam: {exc}", file=sys.stderr)
        return 4 if isinstance(exc, BufferFull) else 1
    torch.cuda.synchronize()
    seconds = time.perf_counter() - t0
    import lietorch
    from mast3r_slam.lietorch_utils import as_SE3

    poses = final_poses(keyframes, relative, lietorch, as_SE3)
    index = np.array(sorted(poses), dtype=int)
    write_tum(args.out, np.asarray(dataset.timestamps, dtype=np.float64)[index], np.array([poses[i] for i in index]))
    print(
        f"mast3r_slam: {len(index)} poses of {len(dataset)} frames ({len(keyframes)} keyframes, "
        f"{len(index) - len(keyframes)} tracked frames) in {seconds:.2f} s ({len(dataset) / seconds:.1f} fps); "
        f"PyTorch's peak allocation {torch.cuda.max_memory_allocated() / 2**20:.0f} MB",
        flush=True,
    )
    return 0


@contextmanager
def retrieval_folder(weights: Path):
    """A temporary working folder whose checkpoints/ links the retrieval head and codebook beside the network (main.py's
    backend loads them from checkpoints/ in its working folder)."""
    import tempfile

    here = os.getcwd()
    with tempfile.TemporaryDirectory(prefix="mast3r-slam-") as tmp:
        (Path(tmp) / "checkpoints").mkdir()
        for f in companions(weights.resolve()):
            (Path(tmp) / "checkpoints" / f.name).symlink_to(f)
        os.chdir(tmp)
        try:
            yield
        finally:
            os.chdir(here)


def frontend(dataset, model, tracker, keyframes, states, backend, relative, buffer, device, Mode, lietorch,
             create_frame, mast3r_inference_mono) -> None:  # fmt: skip
    """main.py's frontend loop without the viewer (single_thread), recording each tracked frame's relative pose."""
    add_new_kf = False
    for i in range(len(dataset)):
        mode = states.get_mode()
        _, img = dataset[i]
        T_WC = lietorch.Sim3.Identity(1, device=device) if i == 0 else states.get_frame().T_WC
        frame = create_frame(i, img, T_WC, img_size=dataset.img_size, device=device)
        if len(keyframes) >= buffer - 1:  # a new keyframe, or a relocalisation's, would not fit
            raise BufferFull(
                f"{len(keyframes)} keyframes fill the buffer of {buffer} at frame {i}: raise params.buffer"
            )
        if mode == Mode.INIT:
            X_init, C_init = mast3r_inference_mono(model, frame)
            frame.update_pointmap(X_init, C_init)
            keyframes.append(frame)
            states.queue_global_optimization(len(keyframes) - 1)
            states.set_mode(Mode.TRACKING)
            states.set_frame(frame)
            continue
        if mode == Mode.TRACKING:
            kf = len(keyframes) - 1
            add_new_kf, _, try_reloc = tracker.track(frame)
            if try_reloc:
                states.set_mode(Mode.RELOC)
            else:
                relative[i] = (kf, (lietorch.Sim3(keyframes.T_WC[kf]).inv() * frame.T_WC).data.clone())
            states.set_frame(frame)
        elif mode == Mode.RELOC:
            X, C = mast3r_inference_mono(model, frame)
            frame.update_pointmap(X, C)
            states.set_frame(frame)
            states.queue_reloc()
            wait_for(backend, lambda: states.reloc_sem.value == 0)
        else:
            raise BackendDied(f"invalid mode {mode!r}")
        if add_new_kf:
            keyframes.append(frame)
            states.queue_global_optimization(len(keyframes) - 1)
            wait_for(backend, lambda: len(states.global_optimizer_tasks) == 0)
    wait_for(backend, lambda: len(states.global_optimizer_tasks) == 0 and states.reloc_sem.value == 0)


def final_poses(keyframes, relative: dict, lietorch, as_SE3) -> dict[int, np.ndarray]:
    """Frame index -> [tx ty tz qx qy qz qw] camera-to-world: the keyframes' optimised poses, and each tracked frame's
    keyframe pose times its pose relative to it (a frame that became a keyframe keeps the keyframe's)."""
    T_WK = lietorch.Sim3(keyframes.T_WC[: len(keyframes)].clone())
    poses = {}
    for frame, (kf, rel) in relative.items():
        T = lietorch.Sim3(T_WK.data[kf]) * lietorch.Sim3(rel)
        poses[frame] = as_SE3(T).data.cpu().numpy().reshape(-1)
    for kf in range(len(keyframes)):
        poses[int(keyframes.dataset_idx[kf])] = as_SE3(lietorch.Sim3(T_WK.data[kf])).data.cpu().numpy().reshape(-1)
    return poses


if __name__ == "__main__":
    sys.exit(run())
