"""MASt3R-SLAM: its patches on the real archives (MASt3R-SLAM with lietorch unpacked into thirdparty/lietorch), what
the patched modules import against what its image installs, its settings against its own config files, the method's
declaration, command and coverage, the GPU memory it is checked against, its weights' three files, and its process on
a real prepared view up to PyTorch (this machine has none) or the missing GPU; and, when the image slamrun/mast3r_slam
has been built, inside it without a GPU: the compiled parts and the modules import, the checkpoints load through
upstream's own loaders, the poses the process writes compose with real lietorch, and the process stops at the missing
GPU."""

from __future__ import annotations

import ast
import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

import slamrun.methods
from slamrun.datasets.cache import prepare
from slamrun.datasets.make_synthetic import generate
from slamrun.datasets.view import Direction, Profile
from slamrun.errors import SlamRunError
from slamrun.images import native
from slamrun.images import sources as src
from slamrun.images.build import BuildOptions, model_choice, pypi_files_of, recipe_text
from slamrun.methods.mast3r_slam import CODEBOOK_NAME, RETRIEVAL_NAME, WEIGHTS_NAME, Mast3rSlam, Mast3rSlamParams
from slamrun.methods.mast3r_slam import process as proc
from tests import images
from tests.conftest import UPSTREAM, recipe, require_upstream
from tests.test_dpvo import changed

RECIPE = recipe("mast3r_slam")
CROCO = "thirdparty/mast3r/dust3r/croco"
DOCKERFILE = RECIPE / "Dockerfile"
IMAGE = "slamrun/mast3r_slam:latest"
# what the torch stages install (recipes/torch_cuda), and the import names of MASt3R-SLAM's own pins
TORCH_STAGE = {"torch", "numpy", "cv2", "einops", "scipy", "packaging", "numba", "pypose"}
PINNED = {"torchvision", "PIL", "faiss", "yaml", "tqdm", "natsort", "plyfile"}
COMPILED = {"lietorch", "lietorch_backends", "mast3r_slam_backends", "curope"}


def unpack(dest: Path) -> Path:
    for name in ("mast3r_slam", "lietorch"):
        require_upstream(UPSTREAM / src.SOURCES[name].filename)
    return native.unpack_only(native.NativeOptions(sources_dir=UPSTREAM, into=dest), "mast3r_slam", log=lambda m: None)


@pytest.fixture(scope="module")
def patched(tmp_path_factory) -> Path:
    return unpack(tmp_path_factory.mktemp("mast3r") / "build")


def top_level_imports(path: Path) -> set[str]:
    """The first name of each module a file imports at its top level (not inside a function or class)."""
    names = set()
    for node in ast.parse(path.read_text()).body:
        if isinstance(node, ast.Import):
            names |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.split(".")[0])
    return names


# ---------------------------------------------------------------- patches on the real archives


def test_patches_build_the_backend_without_a_gpu_for_the_targets_given(patched):
    setup = (patched / "setup.py").read_text()
    assert "has_cuda = True" in setup and "torch.cuda.is_available()" not in setup
    assert "-gencode" not in setup and "EIGEN_INCLUDE_DIR" in setup and "thirdparty/eigen" not in setup
    curope = (patched / f"{CROCO}/models/curope/setup.py").read_text()
    assert "all_cuda_archs = []" in curope and "get_gencode_flags" not in curope.split("all_cuda_archs = []")[1]
    lietorch = (patched / "thirdparty/lietorch/setup.py").read_text()
    assert "-gencode" not in lietorch and "lietorch_extras" not in lietorch
    for cu in ("mast3r_slam/backend/src/matching_kernels.cu", f"{CROCO}/models/curope/kernels.cu"):
        text = (patched / cu).read_text()
        assert "AT_DISPATCH_FLOATING_TYPES_AND_HALF(" in text and not re.search(r"DISPATCH\w*\(\w+\.type\(\)", text)
    gn = (patched / "mast3r_slam/backend/src/gn_kernels.cu").read_text()
    assert "torch::linalg" not in gn and gn.count("at::linalg_norm(") == 3


def test_the_checkpoints_load_with_their_namespaces_and_no_hub(patched):
    assert "weights_only=False" in (patched / "thirdparty/mast3r/mast3r/model.py").read_text()
    assert "weights_only=False" in (patched / "thirdparty/mast3r/mast3r/retrieval/processor.py").read_text()
    assert "huggingface_hub" not in (patched / "thirdparty/mast3r/dust3r/dust3r/model.py").read_text()


def test_what_the_slam_imports_is_what_its_image_installs(patched):
    """Every module main.py and mast3r_slam/*.py import at their top level (the viewer's files aside) is the standard
    library's, the torch stage's, one of the image's pins, compiled here, or MASt3R-SLAM's own; the camera, video and
    viewer packages are imported nowhere at the top."""
    files = [patched / "main.py", *(patched / "mast3r_slam").glob("*.py")]
    files = [f for f in files if not f.name.startswith("visualization")]
    found = set().union(*(top_level_imports(f) for f in files))
    third_party = found - set(sys.stdlib_module_names) - {"mast3r_slam", "mast3r", "dust3r", "asmk"}
    assert third_party <= TORCH_STAGE | PINNED | COMPILED, third_party - TORCH_STAGE - PINNED - COMPILED
    assert not found & {"pyrealsense2", "torchcodec", "imgui", "moderngl", "in3d", "huggingface_hub"}
    pins = {f.project for f in src.pypi_table(src.MAST3R_SLAM)}
    assert pins == {"torchvision", "pillow", "faiss-cpu", "pyyaml", "tqdm", "natsort", "plyfile"}
    assert "from mast3r_slam.visualization" in (patched / "main.py").read_text()  # kept, under __main__


def test_a_moved_anchor_fails_naming_the_file(tmp_path, patched):
    tree = unpack(tmp_path / "again")
    res = subprocess.run([sys.executable, str(RECIPE / "patches.py"), str(tree)], capture_output=True, text=True)
    assert res.returncode != 0 and "lietorch/include/dispatch.h" in res.stderr + res.stdout  # patched already


# ---------------------------------------------------------------- settings, declaration, command


def test_settings_are_its_evaluation_configs_and_code_defaults(patched):
    base = yaml.safe_load((patched / "config/base.yaml").read_text())
    for name in ("eval_calib.yaml", "eval_no_calib.yaml"):
        cfg = yaml.safe_load((patched / "config" / name).read_text())
        assert cfg["single_thread"] is True and cfg["dataset"]["subsample"] == proc.SETTINGS["subsample"]
        assert cfg["use_calib"] is (name == "eval_calib.yaml")
    assert base["tracking"]["match_frac_thresh"] == proc.SETTINGS["match_frac_thresh"]
    assert base["tracking"]["min_match_frac"] == proc.SETTINGS["min_match_frac"]
    assert base["retrieval"]["k"] == proc.SETTINGS["retrieval_k"]
    assert float(base["retrieval"]["min_thresh"]) == proc.SETTINGS["retrieval_min_thresh"]
    assert "buffer=512" in (patched / "mast3r_slam/frame.py").read_text()  # SharedKeyframes' default
    params = Mast3rSlamParams()
    assert params.model_dump(exclude={"weights", "build"}) == proc.SETTINGS
    assert proc.config_file(patched, True).is_file() and proc.config_file(patched, False).is_file()


def test_registered_needing_a_gpu_with_its_image_and_three_weight_files():
    cls = slamrun.methods.REGISTRY["mast3r_slam"]
    assert cls is Mast3rSlam and cls.needs_gpu and cls.native and cls.profile is Profile.rectified
    assert cls.image == IMAGE and cls.native_build.extensions == (
        "lietorch_backends", "mast3r_slam_backends", "curope", "asmk.hamming",
    )  # fmt: skip
    assert cls.network.files == (WEIGHTS_NAME, RETRIEVAL_NAME, CODEBOOK_NAME)
    weights = Path("/w") / WEIGHTS_NAME
    assert proc.companions(weights) == (Path("/w") / RETRIEVAL_NAME, Path("/w") / CODEBOOK_NAME)
    lines = "step\nGPU MEMORY: MASt3R-SLAM needs about 11.2 GiB at 512x384 with a buffer of 512 keyframes\n"
    assert Mast3rSlam().infra_from_log(lines).startswith("GPU MEMORY: MASt3R-SLAM needs about 11.2 GiB")
    assert Mast3rSlam().infra_from_log("Segmentation fault\nKilled") is None


def test_command_carries_every_setting_and_coverage_is_of_the_subsampled_frames(tmp_path):
    view = prepare(generate(tmp_path / "room", frames=12, seed=3), Direction.forward, Profile.rectified, tmp_path / "c")
    params = changed(Mast3rSlamParams)
    argv = Mast3rSlam(params).for_backend("docker").command(view.at("/data"), Path("/work"))
    assert argv[:3] == ["python3", "-m", "slamrun.methods.mast3r_slam.process"]
    assert argv[argv.index("--weights") + 1] == f"/opt/mast3r_slam/weights/{WEIGHTS_NAME}"
    assert json.loads(argv[argv.index("--settings") + 1]) == params
    assert proc.settings(argv[argv.index("--settings") + 1]) == params
    assert list(Mast3rSlam().frames_given(7)) == [0, 2, 4, 6]  # its dataset's rgb_files[::2], the last not added
    assert list(Mast3rSlam({"subsample": 1}).frames_given(3)) == [0, 1, 2]


@pytest.mark.parametrize(
    ("settings", "says"),
    [('{"subsampel": 2}', "unknown setting 'subsampel'"), ('{"buffer": 0}', "buffer: 0 is not a positive integer"),
     ('{"calibrated": "yes"}', "calibrated: 'yes' is not a bool")],
)  # fmt: skip
def test_settings_the_process_cannot_take_are_named(settings, says):
    with pytest.raises(ValueError, match=re.escape(says)):
        proc.settings(settings)


def test_gpu_memory_is_the_buffer_the_network_and_a_margin_at_the_sequences_resolution():
    network = 2_754_973_493  # the stand-in checkpoint's size, the published one's architecture
    need = proc.gpu_bytes_needed(384, 512, 512, network)  # a 640x480 camera resized to 512x384
    per_keyframe = 384 * 512 * 7 * 4 + (384 * 512 // 256) * (1024 * 4 + 16)  # img, X, C; feat and pos per patch
    assert need == 512 * per_keyframe + network + 4 * 2**30
    assert 10 * 2**30 < need < 11 * 2**30  # 10.7 GiB
    assert proc.gpu_bytes_needed(320, 512, 512, network) < need  # EuRoC's 752x480 becomes 512x320
    assert proc.gpu_bytes_needed(384, 512, 64, network) < 8 * 2**30  # a smaller buffer fits a smaller GPU


def test_weights_are_all_three_given_standin_or_an_error_naming_them_and_where(tmp_path):
    all_three = {n: tmp_path / n for n in (WEIGHTS_NAME, RETRIEVAL_NAME, CODEBOOK_NAME)}
    assert model_choice("mast3r_slam", BuildOptions(weights=all_three))[0] == "given"
    with pytest.raises(SlamRunError, match=rf"give {RETRIEVAL_NAME} and {CODEBOOK_NAME} too"):
        model_choice("mast3r_slam", BuildOptions(weights={WEIGHTS_NAME: tmp_path / "x"}))
    kind, detail = model_choice("mast3r_slam", BuildOptions(standin_model=True))
    assert kind == "standin" and "NOT the trained network" in detail
    with pytest.raises(SlamRunError, match=r"needs .*_metric.pth, .*_trainingfree.pth, .*_codebook.pkl.*naverlabs"):
        model_choice("mast3r_slam", BuildOptions())


def test_the_recipe_builds_on_the_torch_stages_and_installs_its_pins_by_hash():
    text = recipe_text(DOCKERFILE)
    assert "FROM torch-cuda AS build" in text and re.search(r"^FROM torch-runtime$", text, re.M)
    table = src.pypi_table(src.MAST3R_SLAM)
    assert pypi_files_of(DOCKERFILE)[-len(table) :] == [f.filename for f in table]
    assert all(src.PYPI_FILES[f.filename] == f for f in table)
    lines = [ln for ln in (RECIPE / "requirements.txt").read_text().splitlines() if ln and not ln.startswith("#")]
    assert "\n".join(lines) + "\n" == src.requirements(list(table))
    assert text.count("--require-hashes --no-deps -r requirements.txt") == 2  # the build stage and the runtime


# ---------------------------------------------------------------- its process on the host


@pytest.fixture(scope="module")
def room_view(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("room")
    return prepare(generate(tmp / "room", frames=20, seed=3), Direction.backward, Profile.rectified, tmp / "cache")


def process(view, build: Path, weights: Path, out: Path, settings: str = "{}") -> subprocess.CompletedProcess:
    argv = [
        sys.executable, "-m", "slamrun.methods.mast3r_slam.process", "--build", str(build), "--weights", str(weights),
        "--images", str(view.path("images")), "--times", str(view.path("times.txt")),
        "--camera", str(view.path("camera_pinhole.json")), "--out", str(out), "--settings", settings,
    ]  # fmt: skip
    return subprocess.run(argv, capture_output=True, text=True)


def test_process_reads_the_view_and_stops_at_missing_files_pytorch_or_the_gpu(tmp_path, room_view, patched):
    weights = tmp_path / WEIGHTS_NAME
    weights.write_bytes(b"x")
    out = tmp_path / "t.txt"
    res = process(room_view, patched.parent, weights, out)
    assert res.returncode == 1 and RETRIEVAL_NAME in res.stderr and CODEBOOK_NAME in res.stderr, res.stderr
    for name in (RETRIEVAL_NAME, CODEBOOK_NAME):
        (tmp_path / name).write_bytes(b"x")
    res = process(room_view, patched.parent, weights, out)
    try:
        import torch  # noqa: F401

        assert res.returncode == 3 and "NO GPU: MASt3R-SLAM" in res.stderr, res.stderr
    except ImportError:
        assert res.returncode == 1 and "PyTorch cannot be imported" in res.stderr, res.stderr
    assert not out.exists()
    res = process(room_view, patched.parent, weights, out, '{"subsample": "2"}')
    assert res.returncode == 1 and "subsample: '2' is not a int" in res.stderr, res.stderr


# ---------------------------------------------------------------- inside the built image (no GPU)


def built_image():
    return images.built_image(IMAGE, "slamrun images --method mast3r_slam --standin-model, about 20 min")


POSES = """
import json, sys
record = json.load(open('/opt/mast3r_slam/build.json'))
tree = '/opt/mast3r_slam/' + record['tree']
sys.path[:0] = [tree, tree + '/thirdparty/mast3r', tree + '/thirdparty/mast3r/asmk', tree + '/thirdparty/lietorch']
import torch, lietorch
import asmk.hamming, lietorch_backends, mast3r_slam_backends, main
from mast3r_slam.lietorch_utils import as_SE3
from models.curope import cuRoPE2D
from slamrun.methods.mast3r_slam.process import final_poses

class Keyframes:  # SharedKeyframes' two fields final_poses reads, for two keyframes (frames 0 and 4)
    def __init__(self, T_WC, ids):
        self.T_WC, self.dataset_idx = T_WC, torch.tensor(ids)
    def __len__(self):
        return len(self.dataset_idx)

poses = json.loads(sys.argv[1])
T = [lietorch.Sim3(torch.tensor([p], dtype=torch.float32)) for p in poses]
kf = Keyframes(torch.stack([T[0].data, T[2].data]), [0, 4])
rel = {2: (0, (T[0].inv() * T[1]).data)}  # frame 2 tracked against keyframe 0
moved = lietorch.Sim3(torch.tensor([[0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 2.0]])) * T[0]  # keyframe 0 re-optimised
kf.T_WC[0] = moved.data
out = final_poses(kf, rel, lietorch, as_SE3)
expected = as_SE3(moved * (T[0].inv() * T[1])).data[0].tolist()
mods = sorted(m for m in ('pyrealsense2', 'torchcodec', 'imgui', 'huggingface_hub') if m in sys.modules)
print(json.dumps({'frames': sorted(out), 'tracked': out[2].tolist(), 'expected': expected, 'kf': out[4].tolist(),
                  'mods': mods, 'record': record}))
"""


def test_the_compiled_parts_import_and_the_poses_compose_with_real_lietorch_inside_the_image():
    """In the image without a GPU: lietorch_backends, mast3r_slam_backends, curope and asmk's hamming import with
    main.py (headless: no camera, video, viewer or Hub package); slamrun's final_poses gives a tracked frame its
    keyframe's final (re-optimised) pose times its relative pose, and a keyframe its own, as SE(3)."""
    api, labels = built_image()
    half = 0.5**0.5
    poses = [[1, 2, 3, 0, 0, half, half, 1.5], [1.5, 2.2, 2.9, 0, 0.1, 0.7, 0.7071, 1.5], [2, 2, 3, 0, 0, 0, 1, 1.2]]
    status, out = images.run_in_image(api, IMAGE, ["python3", "-c", POSES, json.dumps(poses)])
    assert status == 0, out[-3000:]
    got = json.loads(out.strip().splitlines()[-1])
    assert got["frames"] == [0, 2, 4] and got["mods"] == []
    assert np.allclose(got["tracked"], got["expected"], atol=1e-5)
    assert np.allclose(got["kf"], poses[2][:7], atol=1e-5)
    assert got["record"]["arch"] == labels["slamrun.cuda-arch"] == "7.5 8.0 8.6 8.9 9.0"
    label = json.loads(labels["slamrun.weights"])
    assert list(label) == [WEIGHTS_NAME] and "NOT the trained network" in label[WEIGHTS_NAME]
    assert "NOT the trained network" in got["record"]["weights"] and RETRIEVAL_NAME in got["record"]["weights"]


def test_the_checkpoints_load_through_upstreams_loaders_inside_the_image():
    api, _ = built_image()
    status, out = images.run_in_image(api, IMAGE, ["python3", "/opt/mast3r_slam/check_image.py"])
    assert status == 0, out[-3000:]
    assert "689 M parameters" in out.strip().splitlines()[-1]


def test_the_process_in_the_image_reads_a_view_and_stops_at_the_missing_gpu(tmp_path):
    """The image's `python3 -m slamrun.methods.mast3r_slam.process`, as the docker backend runs it, on a real prepared
    view with every parameter other than its default: it reads the settings, the frames and the three checkpoint
    files, imports PyTorch and exits 3 saying there is no GPU (the run then is the machine's: infra_pattern); a setting
    it does not know exits 1, named."""
    api, _ = built_image()
    view = prepare(generate(tmp_path / "room", frames=8, seed=3), Direction.forward, Profile.rectified, tmp_path / "c")
    argv = Mast3rSlam(changed(Mast3rSlamParams)).for_backend("docker").command(view.at("/data"), Path("/tmp"))
    status, out = images.run_in_image(api, IMAGE, argv, {view.root: "/data"})
    assert status == 3 and "NO GPU: MASt3R-SLAM" in out, out[-3000:]
    assert Mast3rSlam().infra_from_log(out).startswith("NO GPU: MASt3R-SLAM runs on CUDA only")
    argv[argv.index("--settings") + 1] = '{"subsampel": 3}'
    status, out = images.run_in_image(api, IMAGE, argv, {view.root: "/data"})
    assert status == 1 and "mast3r_slam: unknown setting 'subsampel'" in out, out[-3000:]


LOOP = """
import json, sys, time
record = json.load(open('/opt/mast3r_slam/build.json'))
tree = '/opt/mast3r_slam/' + record['tree']
sys.path[:0] = [tree, tree + '/thirdparty/mast3r', tree + '/thirdparty/mast3r/asmk', tree + '/thirdparty/lietorch']
from pathlib import Path
import torch, lietorch
from mast3r_slam.frame import Frame, Mode, SharedKeyframes, SharedStates
from mast3r_slam.lietorch_utils import as_SE3
from slamrun.methods.mast3r_slam import process as proc

proc.configured(Path(tree), proc.SETTINGS)  # its evaluation config (the pointmap filter the frames use)
H = W = 16
SCRIPT = json.loads(sys.argv[1])  # per frame: kf, track or lost (the tracker's outcome)
RELOC_AT, BUFFER, DIE = json.loads(sys.argv[2])  # the first frame a relocalisation succeeds at; buffer; backend dies


def sim3(x, z=0.0):
    return lietorch.Sim3(torch.tensor([[x, 0.0, z, 0.0, 0.0, 0.0, 1.0, 1.0]]))


def create_frame(i, img, T_WC, img_size=512, device=None):
    frame = Frame(i, torch.zeros(3, H, W), torch.tensor([[H, W]]), torch.tensor([[H, W]]), torch.zeros(H, W, 3), T_WC)
    frame.feat, frame.pos = torch.zeros(1, 1, 1024), torch.zeros(1, 1, 2, dtype=torch.long)
    return frame


def mono(model, frame):
    return torch.ones(H * W, 3), torch.ones(H * W, 1)


class Tracker:  # the tracker's outcomes as scripted; a tracked camera at x = frame / 10
    def track(self, frame):
        frame.update_pointmap(*mono(None, frame))  # as FrameTracker.track: before it judges the matches
        if SCRIPT[frame.frame_id] == 'lost':
            return False, [], True
        frame.T_WC = sim3(frame.frame_id / 10)
        return SCRIPT[frame.frame_id] == 'kf', [], False


class Dataset:
    img_size = 512
    def __len__(self):
        return len(SCRIPT)
    def __getitem__(self, i):
        return float(i), None


log = []


def backend(states, keyframes):  # main.py's run_backend's protocol with the solver scripted: a task moves its keyframe
    while states.get_mode() is not Mode.TERMINATED:  # 1 up in z (task 0 has no factors: no move); a relocalisation
        mode = states.get_mode()                     # succeeds from frame RELOC_AT on, adding the frame as keyframe
        if mode == Mode.INIT:
            time.sleep(0.01)
            continue
        if mode == Mode.RELOC:
            if states.reloc_sem.value:
                frame = states.get_frame()
                ok = frame.frame_id >= RELOC_AT
                if ok:
                    keyframes.append(frame)
                    states.set_mode(Mode.TRACKING)
                log.append(['reloc', frame.frame_id, ok])
                states.dequeue_reloc()
            time.sleep(0.001)
            continue
        with states.lock:
            idx = states.global_optimizer_tasks[0] if len(states.global_optimizer_tasks) else -1
        if idx == -1:
            time.sleep(0.001)
            continue
        if DIE:
            raise RuntimeError('CUDA error: an illegal memory access was encountered')
        if idx > 0:
            keyframes.T_WC[idx] = (sim3(0.0, 1.0) * lietorch.Sim3(keyframes.T_WC[idx])).data
        log.append(['task', idx])
        with states.lock:
            states.global_optimizer_tasks.pop(0)


manager = proc.LocalManager()
with proc.unshared(torch):
    keyframes = SharedKeyframes(manager, H, W, buffer=BUFFER, device='cpu')
    states = SharedStates(manager, H, W, device='cpu')
thread = proc.Backend(backend, (states, keyframes))
thread.start()
relative = {}
try:
    proc.frontend(Dataset(), None, Tracker(), keyframes, states, thread, relative, BUFFER, 'cpu', Mode, lietorch,
                  create_frame, mono)
    error = None
except (proc.BufferFull, proc.BackendDied) as exc:
    error = f'{type(exc).__name__}: {exc}'
states.set_mode(Mode.TERMINATED)
thread.join(5)
poses = proc.final_poses(keyframes, relative, lietorch, as_SE3)
print(json.dumps({'error': error, 'log': log, 'alive': thread.is_alive(), 'keyframes': len(keyframes),
                  'poses': {i: [round(float(v), 6) for v in p[:3]] for i, p in poses.items()}}))
"""
# frames 0-11: keyframes at 0 (its first), 3 and 9; frame 5 loses the camera, 6 fails to relocalise, 7 succeeds
SCRIPT = ["kf", "track", "track", "kf", "track", "lost", "track", "track", "track", "kf", "track", "track"]


def frontend_loop(api, script, reloc_at=7, buffer=16, die=False):
    args = [json.dumps(script), json.dumps([reloc_at, buffer, die])]
    status, out = images.run_in_image(api, IMAGE, ["python3", "-c", LOOP, *args])
    assert status == 0, out[-3000:]
    return json.loads(out.strip().splitlines()[-1])


def test_the_frontend_loop_keeps_main_pys_order_and_poses_every_tracked_frame_inside_the_image():
    """slamrun's frontend (main.py's loop) with real SharedKeyframes, SharedStates, Frames and lietorch on the CPU,
    its tracker's outcomes and its backend's solver scripted (the GPU's parts): every new keyframe waits for its
    backend task, a lost frame waits for each relocalisation; a tracked frame's pose is its keyframe's final
    (optimised) pose times its pose relative to it at tracking time, a keyframe's its own, and the frames lost or
    relocalising unsuccessfully have none."""
    api, _ = built_image()
    got = frontend_loop(api, SCRIPT)
    assert got["error"] is None and not got["alive"], got
    assert got["log"] == [["task", 0], ["task", 1], ["reloc", 6, False], ["reloc", 7, True], ["task", 3]], got["log"]
    assert got["keyframes"] == 4  # frames 0, 3, 7 (relocalised) and 9
    poses = {int(i): p for i, p in got["poses"].items()}
    assert sorted(poses) == [0, 1, 2, 3, 4, 7, 8, 9, 10, 11]  # 5 lost the camera, 6 did not relocalise
    for i in (1, 2, 4, 8, 10, 11):  # tracked: where the tracker put it, whatever its keyframe's optimisation did
        assert poses[i] == pytest.approx([i / 10, 0.0, 0.0], abs=1e-6), (i, poses[i])
    assert poses[3] == pytest.approx([0.3, 0.0, 1.0]) and poses[9] == pytest.approx([0.9, 0.0, 1.0])  # optimised
    assert poses[0] == pytest.approx([0.0, 0.0, 0.0])


def test_a_full_buffer_and_a_dead_backend_stop_the_frontend_saying_so_inside_the_image():
    api, _ = built_image()
    got = frontend_loop(api, SCRIPT, buffer=4)
    assert got["error"] == "BufferFull: 3 keyframes fill the buffer of 4 at frame 8: raise params.buffer", got
    got = frontend_loop(api, SCRIPT, die=True)
    assert got["error"].startswith("BackendDied: its backend stopped: RuntimeError('CUDA error: an illegal"), got
    assert got["log"] == [] and got["keyframes"] == 2  # frame 3's keyframe waited for a backend that had died


def test_a_native_runs_record_names_its_build_and_what_its_weights_are(tmp_path):
    """run.json of a run on `backend: local` records the native build it ran (source, patches, targets, PyTorch) and
    what its network is (build.json's note: a stand-in says plumbing only), as an image's labels do for `docker`."""
    from slamrun.backends.base import ExecResult
    from slamrun.backends.local import LocalBackend
    from slamrun.engine.execute import _launch_record

    build = tmp_path / "build"
    build.mkdir()
    note = f"untrained stand-ins with {WEIGHTS_NAME}'s interface (...): plumbing only, NOT the trained network"
    record = {"method": "mast3r_slam", "source": "rmurai0610/MASt3R-SLAM@b0ae540", "patches": "p sha256 1",
              "tree": "t", "torch": "2.11.0+cu130", "cuda": "13.0", "arch": "9.0", "weights": note,
              "weights_file": f"weights/{WEIGHTS_NAME}", "python": "/usr/bin/python3", "seconds": 300.0}  # fmt: skip
    (build / "build.json").write_text(json.dumps(record))
    method = Mast3rSlam({"build": str(build)})
    extra = _launch_record(["python3"], None, LocalBackend(), method, ExecResult(exit_code=0, wall_s=1.0))
    assert extra["native_build"] == {"folder": str(build), **{k: record[k] for k in (
        "source", "patches", "torch", "cuda", "arch", "weights")}}  # fmt: skip
    assert "native_build" not in _launch_record(
        ["python3"], None, LocalBackend(), Mast3rSlam({"build": str(tmp_path / "none")}), ExecResult(0, 1.0)
    )  # no build there: nothing to say (the run fails, its log says why)
