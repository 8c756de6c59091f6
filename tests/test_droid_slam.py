"""DROID-SLAM: its patches on the real archives (DROID-SLAM with lietorch in its submodule folder), what the patched
modules import, its pose convention as its code states it, its settings against demo.py, the method's checks and
command, its process on a real prepared view (up to the import of PyTorch, which this machine lacks, or CUDA), its
output read back at the original timestamps, and `slamrun native-build droid_slam`'s unpacking and refusals here."""

from __future__ import annotations

import ast
import json
import py_compile
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import slamrun.methods
from slamrun.core.trajectory import read_tum
from slamrun.datasets.cache import prepare
from slamrun.datasets.make_synthetic import generate
from slamrun.datasets.view import Direction, Profile
from slamrun.images import native
from slamrun.images.sources import SOURCES
from slamrun.methods.droid_slam import DroidSlam, DroidSlamParams
from slamrun.methods.droid_slam import process as proc
from tests.conftest import UPSTREAM, recipe, require_upstream

ROOT = Path(__file__).resolve().parents[1]
PATCHES = recipe("droid_slam") / "patches.py"
TOP = SOURCES["droid_slam"].top
# what DROID's modules may import at their top level once patched: PyTorch, NumPy, OpenCV, lietorch and the two
# compiled extensions, DROID's own flat modules, and the standard library
ALLOWED = {"torch", "numpy", "cv2", "lietorch", "lietorch_backends", "droid_backends"}


def unpack(dest: Path) -> Path:
    require_upstream(UPSTREAM / SOURCES["droid_slam"].filename)
    require_upstream(UPSTREAM / SOURCES["lietorch"].filename)
    opts = native.NativeOptions(sources_dir=UPSTREAM, into=dest)
    return native.unpack_only(opts, "droid_slam", log=lambda m: None)


@pytest.fixture(scope="module")
def patched(tmp_path_factory) -> Path:
    return unpack(tmp_path_factory.mktemp("droid") / "build")


# ---------------------------------------------------------------- patches on the real archives


def test_the_archives_are_the_pinned_commits_and_the_submodules_droid_slam_records():
    for name in ("droid_slam", "lietorch", "pytorch_scatter"):
        assert re.fullmatch(r"[0-9a-f]{40}", SOURCES[name].commit) and re.fullmatch(
            r"[0-9a-f]{64}", SOURCES[name].sha256
        )
    readme = UPSTREAM / "README.md"
    if not readme.is_file():
        pytest.skip(reason=f"{readme} not found: shared/upstream is not beside the repository")
    text = readme.read_text()  # the archives' own record (independent of sources.py)
    for name in ("droid_slam", "lietorch", "pytorch_scatter"):
        assert SOURCES[name].commit in text and SOURCES[name].sha256 in text, name


def test_unpack_only_places_lietorch_in_its_submodule_folder(tmp_path, patched):
    assert patched == patched.parent / TOP
    assert (patched / "thirdparty/lietorch/setup.py").is_file()
    assert (patched / "thirdparty/lietorch/lietorch/groups.py").is_file()
    assert (patched / "droid_slam/_scatter.py").is_file()
    assert not list(patched.parent.glob("lietorch-*"))  # moved, not left beside
    with pytest.raises(native.NativeBuildError, match="is not empty"):
        native.unpack_only(
            native.NativeOptions(sources_dir=UPSTREAM, into=patched.parent), "droid_slam", lambda m: None
        )


def test_patches_make_the_tree_fit_todays_pytorch_and_cuda_13(patched):
    dispatch = (patched / "thirdparty/lietorch/lietorch/include/dispatch.h").read_text()
    assert "::detail::scalar_type" not in dispatch and "at::ScalarType _st = the_type;" in dispatch
    for cu in (patched / "src").glob("*.cu"):
        assert "THC/" not in cu.read_text(), cu
        assert not re.search(r"DISPATCH\w*\([^)]*\.type\(\)", cu.read_text()), cu
    assert "#include <ATen/cuda/Atomic.cuh>" in (patched / "src/altcorr_kernel.cu").read_text()
    lie = (patched / "thirdparty/lietorch/setup.py").read_text()
    assert "-gencode" not in lie  # TORCH_CUDA_ARCH_LIST decides (CUDA 13 has no compute_60/61/70)
    assert "lietorch_extras" not in lie and "lietorch_backends" in lie
    for setup in (lie, (patched / "setup.py").read_text()):
        assert "EIGEN_INCLUDE_DIR" in setup and "eigen')" not in setup
    # the patched setup files still describe the same extensions (their sources exist)
    for folder, exts in native.NATIVE["droid_slam"].setups:
        text = (patched / folder / "setup.py").read_text()
        for ext in exts:
            assert f"CUDAExtension('{ext}'" in text
        for source in re.findall(r"'((?:src|lietorch/src)/[\w./]+)'", text):
            assert (patched / folder / source).is_file(), source


def test_every_python_file_compiles_and_none_imports_torch_scatter(patched, tmp_path):
    files = [*(patched / "droid_slam").rglob("*.py"), *(patched / "thirdparty/lietorch/lietorch").rglob("*.py")]
    assert len(files) > 30
    for py in files:
        py_compile.compile(str(py), cfile=str(tmp_path / "x.pyc"), doraise=True)
        tree = ast.parse(py.read_text())
        names = {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
        names |= {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module}
        assert "torch_scatter" not in names, py


def test_what_droid_imports_runs_headless(patched):
    """From droid.py (what slamrun's process imports), every module reached at import time, followed through DROID's
    flat modules and lietorch: nothing beyond PyTorch, NumPy, OpenCV, lietorch, the extensions and the standard library
    (no matplotlib, scipy, open3d, torch_scatter, tensorboard)."""
    roots = [patched / "droid_slam", patched / "thirdparty/lietorch"]

    def local(name: str) -> Path | None:
        for root in roots:
            for candidate in (root / Path(*name.split("."))).with_suffix(".py"), root / Path(*name.split(".")):
                if candidate.is_file():
                    return candidate
                if (candidate / "__init__.py").is_file():
                    return candidate / "__init__.py"
        return None

    seen, todo, external = set(), ["droid"], set()
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        seen.add(name)
        path = local(name)
        if path is None:
            external.add(name.split(".")[0])
            continue
        pkg = name if path.name == "__init__.py" else name.rpartition(".")[0]
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, ast.Import):
                todo += [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level:
                todo.append(f"{pkg}.{node.module}" if node.module else pkg)
            elif isinstance(node, ast.ImportFrom):
                todo.append(node.module)
    assert {"droid_net", "depth_video", "factor_graph", "modules.corr", "geom.ba", "_scatter"} <= seen
    assert external - set(sys.stdlib_module_names) <= ALLOWED, external - set(sys.stdlib_module_names)
    assert "visualizer.droid_visualizer" not in seen  # open3d: imported only without disable_vis


def test_droids_pose_convention_as_its_code_states_it(patched):
    """The depth video's poses map world points into the camera (projective_transform: X_j = P_j P_i^-1 X_i), and
    terminate() returns them inverted: camera-to-world, lietorch's [tx ty tz qx qy qz qw], which slamrun writes as
    TUM without inverting again (lietorch's inverse on a known case: tests/test_droid_slam_image.py)."""
    ops = (patched / "droid_slam/geom/projective_ops.py").read_text()
    assert "Gij = poses[:, jj] * poses[:, ii].inv()" in ops
    droid = ast.parse((patched / "droid_slam/droid.py").read_text())
    terminate = next(n for n in ast.walk(droid) if isinstance(n, ast.FunctionDef) and n.name == "terminate")
    assert ast.unparse(terminate.body[-1]) == "return camera_trajectory.inv().data.cpu().numpy()"
    filler = (patched / "droid_slam/trajectory_filler.py").read_text()
    assert "t0 = torch.as_tensor([ts[ts<=t].shape[0] - 1 for t in tstamps])" in filler  # by the frames' numbers


def test_a_moved_anchor_or_a_second_run_fails_naming_the_file(tmp_path, patched):
    again = subprocess.run([sys.executable, str(PATCHES), str(patched)], capture_output=True, text=True)
    assert again.returncode != 0 and "dispatch.h" in again.stderr and "found 0 times" in again.stderr
    tree = unpack(tmp_path / "a")  # a fresh tree with one anchor moved, as an upstream change would
    (tree / "thirdparty/lietorch").rename(tmp_path / "lie")
    (tree / "thirdparty/lietorch").mkdir()
    res = subprocess.run([sys.executable, str(PATCHES), str(tree)], capture_output=True, text=True)
    assert res.returncode != 0 and "thirdparty/lietorch/setup.py missing" in res.stderr


# ---------------------------------------------------------------- settings against demo.py


def test_parameters_are_demo_py_defaults(patched):
    demo = (patched / "demo.py").read_text()
    found = dict(re.findall(r'add_argument\("--(\w+)",.*?default=([\d.]+)', demo))
    assert proc.DEMO == {k: type(v)(found[k]) for k, v in proc.DEMO.items()}
    defaults = DroidSlamParams()
    for option, value in proc.DEMO.items():
        assert getattr(defaults, option) == value, option
    assert '"--upsample", action="store_true"' in demo and defaults.upsample is False
    assert "motion_damping" not in demo and defaults.motion_damping == 0.0  # droid_frontend.py's default then
    assert "self.motion_damping = 0.0" in (patched / "droid_slam/droid_frontend.py").read_text()
    assert "np.sqrt((384 * 512) / (h0 * w0))" in demo and proc.AREA == 384 * 512
    assert "if len(tstamps) == 16:" in (patched / "droid_slam/trajectory_filler.py").read_text()
    assert proc.FILL_BATCH == 16


def test_images_are_resized_as_demo_py_does():
    """demo.py: h1 = int(h0 * sqrt(384*512 / (h0*w0))), w1 likewise, cropped to multiples of 8 (worked by hand)."""
    assert proc.resized(480, 640) == (384, 512, 384, 512)
    assert proc.resized(480, 752) == (354, 554, 352, 552)  # EuRoC: scale 0.738020...
    assert proc.resized(1024, 1280) == (396, 495, 392, 488)  # TUM-Mono: scale sqrt(0.15) = 0.387298...
    k = np.array([500.0, 400.0, 320.0, 240.0])
    np.testing.assert_allclose(proc.scaled_intrinsics(k, 480, 752), [500 * 554 / 752, 400 * 354 / 480, 320 * 554 / 752,
                                                                      240 * 354 / 480])  # fmt: skip


# ---------------------------------------------------------------- the method


def test_registered_native_needing_a_gpu_with_an_image_recipe():
    cls = slamrun.methods.get("droid_slam")
    assert cls is DroidSlam and cls.needs_gpu and cls.native and cls.profile is Profile.rectified
    from slamrun.images.build import buildable, weights_of

    assert buildable()["droid_slam"] == ("slamrun/droid_slam:latest", recipe("droid_slam") / "Dockerfile")
    assert weights_of("droid_slam").name == "droid.pth" and weights_of("droid_slam").standin
    with pytest.raises(Exception, match="stride"):
        DroidSlam({"stride": 0})
    with pytest.raises(Exception, match="extra"):
        DroidSlam({"strides": 2})


def fake_build(folder: Path, torch: str | None, weights: bool = True) -> Path:
    """A native build folder as `slamrun native-build droid_slam` leaves it (its record and network file)."""
    folder.mkdir(parents=True)
    record = {"torch": f"{torch}+cu130", "torch_dist": torch, "tree": TOP, "weights_file": "weights/droid.pth"}
    (folder / "build.json").write_text(json.dumps(record))
    if weights:
        (folder / "weights").mkdir()
        (folder / "weights" / "droid.pth").write_bytes(b"net")
    return folder


def test_problems_on_the_local_backend_say_what_to_do(tmp_path):
    from slamrun.methods.native_gpu import installed_torch

    got = DroidSlam({"build": str(tmp_path / "none")}).problems("local")
    assert len(got) == 1 and "droid_slam has no native build" in got[0]
    assert "slamrun native-build droid_slam" in got[0]
    assert DroidSlam().problems("docker") == []
    here = installed_torch()
    if here is None:
        got = DroidSlam({"build": str(fake_build(tmp_path / "a", "2.11.0"))}).problems("local")
        assert "droid_slam runs on PyTorch" in got[0] and "lacks" in got[0]
        return
    assert "holds no network" in DroidSlam({"build": str(fake_build(tmp_path / "c", here, False))}).problems("local")[0]


def test_command_carries_every_setting_and_the_build(tmp_path):
    from tests.test_methods import make_view

    build = fake_build(tmp_path / "build", "x")
    m = DroidSlam({"build": str(build), "stride": 1, "buffer": 300, "upsample": True, "seed": 5}).for_backend("local")
    view = make_view(tmp_path / "v", 1000 + np.arange(40) / 30, Profile.rectified)
    argv = m.command(view, tmp_path / "work")
    assert argv[:3] == [sys.executable, "-m", "slamrun.methods.droid_slam.process"]
    opts = dict(zip(argv[3::2], argv[4::2], strict=True))
    assert opts["--build"] == str(build) and opts["--weights"] == str(build / "weights/droid.pth")
    assert opts["--out"] == str(tmp_path / "work" / "trajectory.txt")
    values = proc.settings(proc.parse(argv[3:]).settings)  # the process reads back exactly what the method set
    assert values == m.params.model_dump(exclude={"build", "weights"})
    assert values["stride"] == 1 and values["buffer"] == 300 and values["upsample"] is True and values["seed"] == 5
    docker = DroidSlam().for_backend("docker").command(view.at("/data"), Path("/work"))
    assert docker[0] == "python3" and "/opt/droid_slam/weights/droid.pth" in docker and "/opt/droid_slam" in docker


def test_every_parameter_is_written_once_and_reaches_droid():
    """Each of DroidSlamParams' fields, set to a value other than its default, reaches DROID's `args` (demo.py's
    namespace) by its name, or the runner (stride, seed): the params model is the one place a parameter is written."""
    from tests.test_dpvo import changed

    values = changed(DroidSlamParams)
    assert len(values) == 16
    got = proc.settings(DroidSlam(values).settings())
    assert got == values
    args = vars(proc.droid_args(got, Path("/w/droid.pth"), (48, 64)))
    assert {name: args[name] for name in values if name not in ("stride", "seed")} == {
        name: value for name, value in values.items() if name not in ("stride", "seed")
    }
    assert args["weights"] == "/w/droid.pth" and args["image_size"] == [48, 64] and args["disable_vis"] is True


@pytest.mark.parametrize(
    ("settings", "says"),
    [
        ('{"strides": 2}', "unknown setting 'strides'"),
        ('{"buffer": 2.5}', "setting buffer: 2.5 is not a int"),
        ('{"upsample": "1"}', "setting upsample: '1' is not a bool"),
        ('{"warmup": 0}', "setting warmup: 0 is not a positive integer"),
    ],
)
def test_settings_the_process_cannot_take_are_named(settings, says):
    with pytest.raises(ValueError, match=re.escape(says)):
        proc.settings(settings)


# ---------------------------------------------------------------- the process, up to PyTorch and CUDA


@pytest.fixture(scope="module")
def room_view(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("room")
    seq = generate(tmp / "room", frames=40, seed=3)
    return prepare(seq, Direction.backward, Profile.rectified, tmp / "cache")


def process_argv(view, build: Path, weights: Path, out: Path, times: Path | None = None) -> list[str]:
    return [
        sys.executable, "-m", "slamrun.methods.droid_slam.process", "--build", str(build), "--weights", str(weights),
        "--images", str(view.path("images")), "--times", str(times or view.path("times.txt")),
        "--camera", str(view.path("camera_pinhole.json")), "--out", str(out),
    ]  # fmt: skip


def test_process_reads_the_view_and_stops_at_pytorch_or_the_gpu(tmp_path, room_view, patched):
    weights = tmp_path / "droid.pth"
    weights.write_bytes(b"x")
    out = tmp_path / "t.txt"
    res = subprocess.run(process_argv(room_view, patched.parent, weights, out), capture_output=True, text=True)
    try:
        import torch  # noqa: F401

        assert res.returncode == 3 and "NO GPU" in res.stderr, res.stderr
    except ImportError:
        assert res.returncode == 1 and "PyTorch cannot be imported" in res.stderr, res.stderr
    assert not out.exists()
    short = tmp_path / "times.txt"
    short.write_text("\n".join(room_view.path("times.txt").read_text().splitlines()[:-1]) + "\n")
    res = subprocess.run(process_argv(room_view, patched.parent, weights, out, short), capture_output=True, text=True)
    assert res.returncode == 1 and "40 frames but 39 timestamps" in res.stderr
    res = subprocess.run(
        process_argv(room_view, patched.parent, tmp_path / "no.pth", out), capture_output=True, text=True
    )
    assert res.returncode == 1 and f"weights {tmp_path / 'no.pth'} not found" in res.stderr


def test_search_path_is_the_builds_tree_with_lietorch_and_droids_flat_modules(tmp_path):
    build = fake_build(tmp_path / "b", "x")
    tree = build / TOP
    assert proc.search_path(build) == [str(tree / "thirdparty/lietorch"), str(tree / "droid_slam"), str(tree)]
    assert proc.search_path(build) == [
        str(tree / p) if p != "." else str(tree) for p in native.NATIVE["droid_slam"].import_path
    ]


def test_every_frames_pose_reads_back_at_the_original_timestamps(tmp_path, room_view):
    """terminate() given every frame returns one camera-to-world row per frame ([tx ty tz qx qy qz qw]): written as TUM
    at the view's times, the method reads them back at the original (backward view) timestamps, positions as given."""
    paths, times = proc.frames(room_view.path("images"), room_view.path("times.txt"), 1)
    assert len(paths) == 40
    rng = np.random.default_rng(0)
    centres = np.cumsum(rng.normal(0, 0.05, (40, 3)), axis=0)
    quats = rng.normal(size=(40, 4))
    quats /= np.linalg.norm(quats, axis=1, keepdims=True)
    work = tmp_path / "work"
    work.mkdir()
    proc.write_tum(work / "trajectory.txt", times, np.column_stack([centres, quats]))
    traj = DroidSlam().read_trajectory(work, room_view)
    original = np.loadtxt(room_view.path("original_times.txt"))
    assert len(traj) == 40
    np.testing.assert_allclose(np.sort(traj.timestamps), np.sort(original), atol=1e-9)
    raw = read_tum(work / "trajectory.txt")
    np.testing.assert_allclose(raw.timestamps, times)
    np.testing.assert_allclose(raw.positions, centres)


# ---------------------------------------------------------------- native-build droid_slam here


def test_cli_unpack_only_checks_patches_and_refuses_a_used_folder(tmp_path):
    require_upstream(UPSTREAM / SOURCES["droid_slam"].filename)
    argv = [
        sys.executable,
        "-m",
        "slamrun.cli",
        "native-build",
        "droid_slam",
        "--unpack-only",
        "--sources",
        str(UPSTREAM),
    ]
    res = subprocess.run([*argv, "--into", str(tmp_path / "t")], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert "patched DROID-SLAM-" in res.stdout and "14 edits" in res.stdout
    assert (tmp_path / "t" / TOP / "thirdparty/lietorch/setup.py").is_file()
    res = subprocess.run([*argv, "--into", str(tmp_path / "t")], capture_output=True, text=True)
    assert res.returncode == 1 and "is not empty" in res.stderr and "Traceback" not in res.stderr
    empty = tmp_path / "src"
    empty.mkdir()
    res = subprocess.run([*argv[:-1], str(empty), "--into", str(tmp_path / "u")], capture_output=True, text=True)
    assert res.returncode == 1 and f"{empty / SOURCES['droid_slam'].filename}: missing" in res.stderr


def test_native_build_refuses_a_cpu_pytorch_in_one_line(tmp_path):
    res = subprocess.run(
        [sys.executable, "-m", "slamrun.cli", "native-build", "droid_slam", "--standin-model", "--arch", "9.0",
         "--into", str(tmp_path / "b")],
        capture_output=True, text=True,
    )  # fmt: skip
    assert res.returncode == 1 and len(res.stderr.strip().splitlines()) == 1, res.stderr
    assert re.search(r"is a CPU build: DROID-SLAM needs a CUDA build|cannot import PyTorch", res.stderr), res.stderr
    assert not (tmp_path / "b").exists()


def test_native_build_without_weights_names_droid_pth_and_where_it_is_published(tmp_path):
    from slamrun.errors import SlamRunError

    with pytest.raises(SlamRunError, match=r"droid_slam needs droid.pth.*--standin-model.*download_model.sh"):
        native.build("droid_slam", native.NativeOptions(into=tmp_path / "b"), log=lambda m: None)
    with pytest.raises(native.NativeBuildError, match="no native build for 'orb_slam2'.*dpvo, droid_slam"):
        native.build("orb_slam2", native.NativeOptions(into=tmp_path / "b"), log=lambda m: None)


def test_every_declared_native_recipe_is_built_by_the_cli():
    assert set(native.NATIVE) == {"dpvo", "droid_slam", "mast3r_slam"}  # the methods declaring a native_build
    for name, m in native.NATIVE.items():
        assert slamrun.methods.get(name).native and m.patches.is_file() and m.standin.is_file()
        assert slamrun.methods.get(name)().default_build().name == name  # a folder of its own, named by the method


# ---------------------------------------------------------------- the process's own logic, DROID and PyTorch faked

FAKE_TORCH = '''"""A stand-in for PyTorch: just what slamrun's DROID-SLAM process calls itself (NumPy underneath)."""
import numpy as np

__version__ = "0+fake"


class Tensor:
    def __init__(self, a):
        self.a = np.asarray(a)

    shape = property(lambda self: self.a.shape)

    def permute(self, *dims):
        return Tensor(self.a.transpose(dims))

    def __getitem__(self, key):
        return Tensor(self.a[key])


def as_tensor(a):
    return Tensor(a)


def manual_seed(seed):
    pass


class cuda:
    is_available = staticmethod(lambda: True)
    synchronize = staticmethod(lambda: None)
    max_memory_allocated = staticmethod(lambda: 0)
'''

FAKE_DROID = '''"""A stand-in for DROID's Droid: each tracked frame a keyframe; terminate() numbers the frames given."""
import json
from types import SimpleNamespace

import numpy as np


class Droid:
    def __init__(self, args):
        self.args, self.tracked = args, []
        self.video = SimpleNamespace(counter=SimpleNamespace(value=0))
        self.frontend = SimpleNamespace(is_initialized=False)

    def track(self, t, image, intrinsics=None):
        assert image.shape == (1, 3, *self.args.image_size), image.shape
        self.tracked.append(int(t))
        self.video.counter.value = len(self.tracked)
        self.frontend.is_initialized = len(self.tracked) >= self.args.warmup

    def terminate(self, stream):
        filled = [(int(t), intr.a.tolist()) for t, image, intr in stream]
        print("FAKE", json.dumps({"tracked": self.tracked, "filled": [t for t, _ in filled], "intr": filled[0][1],
                                  "args": vars(self.args)}))
        poses = np.zeros((len(filled), 7))
        poses[:, 0] = [t for t, _ in filled]
        poses[:, 6] = 1.0
        return poses
'''


@pytest.fixture
def fake_droid(tmp_path) -> Path:
    """A build folder whose tree holds the fakes where DROID's flat modules go (ahead of everything on sys.path)."""
    build = fake_build(tmp_path / "fake", "x")
    (build / TOP / "droid_slam").mkdir(parents=True)
    (build / TOP / "droid_slam" / "torch.py").write_text(FAKE_TORCH)
    (build / TOP / "droid_slam" / "droid.py").write_text(FAKE_DROID)
    return build


def test_process_tracks_every_strided_frame_and_writes_every_frames_pose(tmp_path, room_view, fake_droid):
    out = tmp_path / "t.txt"
    argv = process_argv(room_view, fake_droid, fake_droid / "weights/droid.pth", out)
    res = subprocess.run([*argv, "--settings", '{"stride": 3, "upsample": true}'], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    fake = json.loads(next(ln for ln in res.stdout.splitlines() if ln.startswith("FAKE "))[5:])
    assert fake["tracked"] == list(range(0, 40, 3))  # demo.py's [::stride]
    assert fake["filled"] == list(range(40))  # terminate() is given every frame
    cam = json.loads(room_view.path("camera_pinhole.json").read_text())
    h1, w1, h, w = proc.resized(cam["height"], cam["width"])
    assert fake["args"]["image_size"] == [h, w] and fake["args"]["upsample"] is True
    assert fake["args"]["disable_vis"] is True and fake["args"]["stereo"] is False and fake["args"]["warmup"] == 8
    sx, sy = w1 / cam["width"], h1 / cam["height"]
    np.testing.assert_allclose(fake["intr"], [cam["fx"] * sx, cam["fy"] * sy, cam["cx"] * sx, cam["cy"] * sy])
    raw = read_tum(out)
    np.testing.assert_allclose(raw.timestamps, room_view.view_timestamps())  # one row per frame, in order
    np.testing.assert_allclose(raw.positions[:, 0], np.arange(40))  # row i is frame i's pose
    assert "droid_slam: 40 poses (14 keyframes)" in res.stdout


def test_process_says_not_initialized_and_a_full_buffer(tmp_path, room_view, fake_droid):
    argv = process_argv(room_view, fake_droid, fake_droid / "weights/droid.pth", tmp_path / "t.txt")
    res = subprocess.run([*argv, "--settings", '{"warmup": 20}'], capture_output=True, text=True)  # 14 frames tracked
    assert res.returncode == 2 and "NOT INITIALIZED: DROID-SLAM kept 14 keyframe(s), it starts at 20" in res.stdout
    assert DroidSlam().failure_from_log(res.stdout) == "not_initialized"
    res = subprocess.run([*argv, "--settings", '{"stride": 1, "buffer": 50}'], capture_output=True, text=True)
    assert res.returncode == 4 and "40 keyframes fill the buffer of 50" in res.stderr and "params.buffer" in res.stderr
    assert not (tmp_path / "t.txt").exists()
