"""DPVO: its patches on the real archive, the torch_scatter stand-in against pytorch_scatter's own code, its settings
against its authors' files, the method's checks and command, its runner on a real prepared view (up to the import of
DPVO's CUDA code, which needs a GPU), and the native build's refusals on this machine (no CUDA build of PyTorch)."""

from __future__ import annotations

import ast
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

import slamrun.methods
from slamrun.core.trajectory import read_tum
from slamrun.datasets.cache import prepare
from slamrun.datasets.make_synthetic import generate
from slamrun.datasets.view import Direction, Profile
from slamrun.images import native
from slamrun.images.sources import SOURCES
from slamrun.methods.dpvo import Dpvo, DpvoParams
from slamrun.methods.dpvo import process as dpvo_process
from slamrun.methods.native_gpu import native_problems as gpu_native_problems
from tests.conftest import recipe, require_upstream, unpack_upstream

ROOT = Path(__file__).resolve().parents[1]
PATCHES = recipe("dpvo") / "patches.py"
COMPAT = recipe("torch_cuda") / "torch_scatter_compat.py"


def patch_tree(dest: Path) -> Path:
    tree = unpack_upstream("dpvo", dest)
    res = subprocess.run([sys.executable, str(PATCHES), str(tree)], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    return tree


@pytest.fixture(scope="module")
def patched(tmp_path_factory) -> Path:
    return patch_tree(tmp_path_factory.mktemp("dpvo"))


# ---------------------------------------------------------------- patches on the real archive


def test_patches_make_the_tree_fit_todays_pytorch(patched):
    for rel in (
        "dpvo/altcorr/correlation_kernel.cu",
        "dpvo/lietorch/src/lietorch_gpu.cu",
        "dpvo/lietorch/src/lietorch_cpu.cpp",
    ):
        text = (patched / rel).read_text()
        assert not re.search(r"DISPATCH\w*\([^)]*\.type\(\)", text), rel  # no x.type() left in a dispatch
        assert ".scalar_type()" in text
    assert "::detail::scalar_type" not in (patched / "dpvo/lietorch/include/dispatch.h").read_text()
    assert "THC/" not in (patched / "dpvo/altcorr/correlation_kernel.cu").read_text()
    setup = (patched / "setup.py").read_text()
    assert "osp.join(ROOT, 'thirdparty/eigen" not in setup and "EIGEN_INCLUDE_DIR" in setup
    for py in (patched / "dpvo").rglob("*.py"):  # every module parses; none but the classic loop closure's (DBoW2,
        if "loop_closure" in py.parts:  # kornia: not built) imports torch_scatter
            continue
        tree = ast.parse(py.read_text())
        names = {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
        names |= {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module}
        assert "torch_scatter" not in names, py
    top = ast.parse((patched / "dpvo/patchgraph.py").read_text()).body
    top_imports = {ast.unparse(n) for n in top if isinstance(n, ast.Import | ast.ImportFrom)}
    assert not any("einops" in i or "optim_utils" in i for i in top_imports), top_imports
    assert "autocast = torch.cuda.amp.autocast" not in (patched / "dpvo/dpvo.py").read_text()
    net = ast.parse((patched / "dpvo/net.py").read_text())  # DPVO's process imports it: no matplotlib needed
    assert not [n for n in ast.walk(net) if isinstance(n, ast.Import) and any("matplotlib" in a.name for a in n.names)]


def test_a_moved_anchor_or_a_second_run_fails_naming_the_file(tmp_path, patched):
    again = subprocess.run([sys.executable, str(PATCHES), str(patched)], capture_output=True, text=True)
    assert again.returncode != 0 and "correlation_kernel.cu" in again.stderr
    tree = unpack_upstream("dpvo", tmp_path)
    blocks = tree / "dpvo/blocks.py"
    blocks.write_text(blocks.read_text().replace("import torch_scatter\n", "import torch_scatter as ts\n"))
    res = subprocess.run([sys.executable, str(PATCHES), str(tree)], capture_output=True, text=True)
    assert res.returncode != 0 and "dpvo/blocks.py" in res.stderr and "found 0 times" in res.stderr


def test_the_patched_package_lacks_only_the_compiled_extensions(patched):
    """Imported on this machine's PyTorch (a CPU build): DPVO's Python code needs nothing but its own extensions
    (no torch_scatter, einops, numba, pypose, yacs), and its SoftAgg runs on the torch_scatter stand-in."""
    pytest.importorskip("torch")
    code = (
        "import sys; sys.path.insert(0, sys.argv[1]); import torch\n"
        "import dpvo.blocks, dpvo.utils\n"
        "torch.manual_seed(0); agg = dpvo.blocks.SoftAgg(4)\n"
        "x = torch.randn(1, 6, 4); ix = torch.tensor([3, 1, 3, 2, 1, 3])\n"
        "y = agg(x, ix)\n"
        "_, jx = torch.unique(ix, return_inverse=True); w = torch.zeros(1, 6, 4); g = agg.g(x)\n"
        "for k in range(3):\n"
        "    m = jx == k; w[:, m] = torch.softmax(g[:, m], dim=1)\n"
        "s = torch.zeros(1, 3, 4).index_add_(1, jx, agg.f(x) * w)\n"
        "assert torch.allclose(y, agg.h(s)[:, jx], atol=1e-6)\n"
        "try:\n    import dpvo.dpvo\nexcept ModuleNotFoundError as e:\n    print('missing', e.name)\n"
    )
    res = subprocess.run([sys.executable, "-c", code, str(patched)], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert res.stdout.split() in (["missing", "cuda_corr"], ["missing", "cuda_ba"], ["missing", "lietorch_backends"])


# ---------------------------------------------------------------- the torch_scatter stand-in


def pytorch_scatter_sum(tmp_path: Path):
    """rusty1s/pytorch_scatter's own scatter_sum and broadcast (pure Python there), from the pinned archive."""
    archive = require_upstream(Path(os.environ.get("SLAMRUN_SHARED", ROOT.parent / "shared")) / "upstream")
    name = next(p.name for p in archive.glob("pytorch_scatter-*.tar.gz"))
    import tarfile

    with tarfile.open(archive / name) as tar:
        top = name.removesuffix(".tar.gz")
        utils = tar.extractfile(f"{top}/torch_scatter/utils.py").read().decode()
        scatter = tar.extractfile(f"{top}/torch_scatter/scatter.py").read().decode()
    ns: dict = {}
    exec(utils, ns)
    body = scatter.split("def scatter_add(")[0].replace("from .utils import broadcast", "")
    exec(body, ns)
    return ns["scatter_sum"]


def load_compat():
    import importlib.util

    spec = importlib.util.spec_from_file_location("torch_scatter_compat", COMPAT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_scatter_sum_matches_pytorch_scatter(tmp_path):
    torch = pytest.importorskip("torch")
    reference = pytorch_scatter_sum(tmp_path)
    compat = load_compat()
    g = torch.Generator().manual_seed(1)
    src = torch.randn(2, 9, 5, generator=g, dtype=torch.float64)
    index = torch.tensor([4, 0, 4, 1, 1, 0, 3, 4, 0])
    for kwargs in ({"dim": 1}, {"dim": 1, "dim_size": 7}, {"dim": -2}):
        assert torch.equal(compat.scatter_sum(src, index, **kwargs), reference(src, index, **kwargs)), kwargs
    flat = torch.randn(9, generator=g)
    assert torch.equal(compat.scatter_sum(flat, index, dim=0), reference(flat, index, dim=0))


def test_scatter_softmax_is_a_softmax_within_each_group():
    torch = pytest.importorskip("torch")
    compat = load_compat()
    src = torch.tensor([[[1.0, -2.0], [3.0, 0.5], [-1.0, 4.0], [2.0, 2.0], [0.0, -3.0]]], dtype=torch.float64)
    index = torch.tensor([2, 0, 2, 0, 2])
    got = compat.scatter_softmax(src, index, dim=1).numpy()[0]
    x = src.numpy()[0]
    for group in (0, 2):  # numpy: exp(x - max) / sum over the group's rows, per column
        rows = np.flatnonzero(index.numpy() == group)
        e = np.exp(x[rows] - x[rows].max(axis=0))
        np.testing.assert_allclose(got[rows], e / e.sum(axis=0), rtol=1e-12)
    with pytest.raises(ValueError, match="floating point"):
        compat.scatter_softmax(torch.ones(3, dtype=torch.long), torch.tensor([0, 0, 1]))


# ---------------------------------------------------------------- settings against the authors' files


def test_settings_are_the_authors_defaults(patched):
    """dpvo_process.CONFIG is dpvo/config.py; the parameters' defaults are config/default.yaml's (config.py's where
    the YAML is silent), demo.py's stride."""
    tree = ast.parse((patched / "dpvo/config.py").read_text())
    upstream = {
        n.targets[0].attr: ast.literal_eval(n.value)
        for n in tree.body
        if isinstance(n, ast.Assign) and isinstance(n.targets[0], ast.Attribute)
    }
    assert dpvo_process.CONFIG == upstream
    demo = yaml.safe_load((patched / "config/default.yaml").read_text())
    defaults = DpvoParams()
    _, cfg = dpvo_process.config(Dpvo().settings())
    for key in dpvo_process.CONFIG:
        assert getattr(cfg, key) == demo.get(key, upstream[key]), key  # what slamrun runs: default.yaml's
    stride = re.search(r"'--stride', type=int, default=(\d+)", (patched / "demo.py").read_text())
    assert defaults.stride == int(stride.group(1))


# ---------------------------------------------------------------- the method


def test_registered_native_needing_a_gpu_with_an_image_recipe():
    cls = slamrun.methods.get("dpvo")
    assert cls is Dpvo and cls.needs_gpu is True and cls.native and cls.profile is Profile.rectified
    assert Dpvo().problems("docker") == []  # slamrun/methods/dpvo/image/Dockerfile (tests/test_dpvo_image.py)
    from slamrun.images.build import buildable

    assert buildable()["dpvo"] == ("slamrun/dpvo:latest", recipe("dpvo") / "Dockerfile")


def fake_build(folder: Path, torch: str | None, weights: bool = True) -> Path:
    """A native build folder as `slamrun native-build dpvo` leaves it (its record and network file)."""
    folder.mkdir(parents=True)
    record = {"torch": f"{torch}+cu130", "torch_dist": torch, "tree": "t", "weights_file": "weights/dpvo.pth"}
    (folder / "build.json").write_text(json.dumps(record))
    if weights:
        (folder / "weights").mkdir()
        (folder / "weights" / "dpvo.pth").write_bytes(b"net")
    return folder


def test_native_problems_say_what_to_do(tmp_path):
    from slamrun.methods.native_gpu import installed_torch

    assert "no native build" in problems(tmp_path / "none", None)[0]
    assert "slamrun native-build dpvo" in problems(tmp_path / "none", None)[0]
    here = installed_torch()
    if here is None:
        assert "lacks" in problems(fake_build(tmp_path / "a", "2.11.0"), None)[0]
        return
    assert "made for PyTorch 0.1" in problems(fake_build(tmp_path / "b", "0.1"), None)[0]
    assert "holds no network" in problems(fake_build(tmp_path / "c", here, weights=False), None)[0]
    assert "params.weights: /nope.pth not found" in problems(fake_build(tmp_path / "d", here), "/nope.pth")[0]
    assert problems(tmp_path / "d", None) == []


def changed(params: type) -> dict:
    """A value other than its default for each parameter a GPU method hands its process (all but build, weights)."""
    import typing

    out = {}
    for name, field in params.model_fields.items():
        default, kind = field.default, field.annotation
        if name in ("build", "weights"):
            continue
        if typing.get_origin(kind) is typing.Literal:
            out[name] = next(choice for choice in typing.get_args(kind) if choice != default)
        elif default is None:
            out[name] = 7
        elif isinstance(default, bool):
            out[name] = not default
        else:
            out[name] = default + (1 if isinstance(default, int) else 0.25)
    return out


def test_command_carries_the_settings_and_the_build(tmp_path):
    build = fake_build(tmp_path / "build", "x")
    m = Dpvo({"build": str(build), "stride": 1, "patches_per_frame": 64, "seed": 3}).for_backend("local")
    from tests.test_methods import make_view

    view = make_view(tmp_path / "v", 1000 + np.arange(40) / 30, Profile.rectified)
    argv = m.command(view, tmp_path / "work")
    assert argv[:3] == [sys.executable, "-m", "slamrun.methods.dpvo.process"]
    opts = dict(zip(argv[3::2], argv[4::2], strict=True))
    assert opts["--build"] == str(build) and opts["--weights"] == str(build / "weights/dpvo.pth")
    assert opts["--camera"] == str(view.path("camera_pinhole.json"))
    args = dpvo_process.parse(argv[3:])
    runner, cfg = dpvo_process.config(args.settings)
    assert runner == {"stride": 1, "seed": 3} and cfg.PATCHES_PER_FRAME == 64
    docker = Dpvo().for_backend("docker").command(view.at("/data"), Path("/work"))
    assert docker[0] == "python3" and "/opt/dpvo/weights/dpvo.pth" in docker


def test_every_parameter_is_written_once_and_reaches_dpvo():
    """Each of DpvoParams' fields, set to a value other than its default, reaches the process as it is: the runner's
    (stride, seed) or DPVO's cfg under its config.py name. The params model is the one place a parameter is written:
    the command hands them all as one JSON object, the process knows DPVO's names."""
    values = changed(DpvoParams)
    assert len(values) == 17
    runner, cfg = dpvo_process.config(Dpvo(values).settings())
    got = runner | {key.lower(): value for key, value in vars(cfg).items()}
    assert {name: got[name] for name in values} == values
    untouched = {key: value for key, value in vars(cfg).items() if key.lower() not in values}
    assert untouched == {key: dpvo_process.CONFIG[key] for key in untouched}  # config.py's: the classical one off


@pytest.mark.parametrize(
    ("settings", "says"),
    [
        ('{"patches_per_frame": 64, "patch_count": 3}', "unknown setting 'patch_count'"),
        ('{"PATCHES_PER_FRAME": 64}', "unknown setting 'PATCHES_PER_FRAME'"),
        ('{"patches_per_frame": "64"}', "setting patches_per_frame: '64' is not a int"),
        ('{"mixed_precision": 1}', "setting mixed_precision: 1 is not a bool"),
        ('{"stride": 0}', "setting stride: 0 is not a positive integer"),
        ("[1]", "a JSON object expected"),
        ("{patches", "Expecting property name"),
    ],
)
def test_settings_the_process_cannot_take_are_named(settings, says):
    with pytest.raises(ValueError, match=re.escape(says)):
        dpvo_process.config(settings)
    assert dpvo_process.config('{"keyframe_thresh": 15}')[1].KEYFRAME_THRESH == 15  # an integer where a number is meant


# ---------------------------------------------------------------- the runner, up to DPVO's CUDA code


@pytest.fixture(scope="module")
def room_view(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("room")
    seq = generate(tmp / "room", frames=40, seed=3)
    return prepare(seq, Direction.backward, Profile.rectified, tmp / "cache")


def test_runner_reads_the_view_and_stops_at_the_missing_gpu(tmp_path, room_view, patched):
    paths, times = dpvo_process.frames(room_view.path("images"), room_view.path("times.txt"), 3)
    assert len(paths) == 14 and paths[-1].name == "000039.png"  # every 3rd frame (39 is one)
    np.testing.assert_array_equal(times, room_view.view_timestamps()[list(range(0, 40, 3))])
    paths, _ = dpvo_process.frames(room_view.path("images"), room_view.path("times.txt"), 7)
    assert [p.name for p in paths[-2:]] == ["000035.png", "000039.png"]  # the last frame always
    weights = tmp_path / "dpvo.pth"
    weights.write_bytes(b"x")
    argv = [
        sys.executable, "-m", "slamrun.methods.dpvo.process", "--build", str(patched.parent), "--weights", str(weights),
        "--images", str(room_view.path("images")), "--times", str(room_view.path("times.txt")),
        "--camera", str(room_view.path("camera_pinhole.json")), "--out", str(tmp_path / "t.txt"),
    ]  # fmt: skip
    res = subprocess.run(argv, capture_output=True, text=True, cwd=tmp_path)
    try:
        import torch  # noqa: F401

        assert res.returncode == 3 and "NO GPU" in res.stderr, res.stderr  # torch imported, no CUDA device
    except ImportError:
        assert res.returncode == 1 and "PyTorch cannot be imported" in res.stderr, res.stderr
    assert not (tmp_path / "t.txt").exists()
    short = tmp_path / "times.txt"
    short.write_text("\n".join(room_view.path("times.txt").read_text().splitlines()[:-1]) + "\n")
    res = subprocess.run([*argv[:10], str(short), *argv[11:]], capture_output=True, text=True, cwd=tmp_path)
    assert res.returncode == 1 and "40 frames but 39 timestamps" in res.stderr
    res = subprocess.run([*argv, "--settings", '{"patch_count": 3}'], capture_output=True, text=True, cwd=tmp_path)
    assert res.returncode == 1 and "dpvo: unknown setting 'patch_count'" in res.stderr, res.stderr
    missing = dpvo_process.missing_for_loop_closure()  # DPV-SLAM's modules: in the image, not in this environment
    res = subprocess.run([*argv, "--settings", '{"loop_closure": true}'], capture_output=True, text=True, cwd=tmp_path)
    if missing:  # refused before PyTorch or the GPU is looked at: bad input, named
        assert res.returncode == 1 and f"loop_closure (DPV-SLAM) needs {', '.join(missing)}" in res.stderr
    else:
        assert res.returncode in (1, 3) and "loop_closure" not in res.stderr, res.stderr


def test_runner_output_reads_back_at_the_original_timestamps(tmp_path, room_view):
    """DPVO's terminate() gives (poses x y z qx qy qz qw, the fed frames' indices): written as TUM at the view's
    times, the method's reader maps them back to the original (backward view) timestamps."""
    paths, times = dpvo_process.frames(room_view.path("images"), room_view.path("times.txt"), 2)
    poses = np.zeros((len(paths), 7))
    poses[:, 0] = np.arange(len(paths))
    poses[:, 6] = 1.0
    work = tmp_path / "work"
    work.mkdir()
    dpvo_process.write_tum(work / "trajectory.txt", times[np.arange(len(paths))], poses)
    traj = Dpvo().read_trajectory(work, room_view)
    original = np.loadtxt(room_view.path("original_times.txt"))
    assert len(traj) == 21
    assert set(np.round(traj.timestamps, 9)) <= set(np.round(original, 9))
    raw = read_tum(work / "trajectory.txt")
    np.testing.assert_allclose(raw.timestamps, times)


# ---------------------------------------------------------------- the native build's refusals here


def test_native_build_refuses_a_cpu_pytorch_in_one_line(tmp_path):
    res = subprocess.run(
        [sys.executable, "-m", "slamrun.cli", "native-build", "dpvo", "--standin-model", "--arch", "9.0",
         "--into", str(tmp_path / "b")],
        capture_output=True, text=True,
    )  # fmt: skip
    assert res.returncode == 1 and len(res.stderr.strip().splitlines()) == 1, res.stderr
    assert re.search(r"is a CPU build: DPVO needs a CUDA build|cannot import PyTorch", res.stderr), res.stderr
    assert not (tmp_path / "b").exists()


def test_native_build_without_weights_names_where_they_are_published(tmp_path):
    with pytest.raises(native.NativeBuildError.__mro__[1], match=r"dpvo needs dpvo.pth.*--standin-model.*models.zip"):
        native.build("dpvo", native.NativeOptions(into=tmp_path / "b"), log=lambda m: None)


def test_eigen_and_toolkit_lookups_say_what_is_missing(tmp_path, monkeypatch):
    with pytest.raises(native.NativeBuildError, match=f"{tmp_path} holds no Eigen/Core.*--eigen DIR"):
        native.eigen_dir(tmp_path)
    (tmp_path / "Eigen").mkdir()
    (tmp_path / "Eigen" / "Core").write_text("")
    assert native.eigen_dir(tmp_path) == tmp_path.resolve()
    monkeypatch.setenv("CUDA_HOME", str(tmp_path))
    with pytest.raises(native.NativeBuildError, match="holds no bin/nvcc"):
        native.cuda_home()


def test_unpack_only_checks_and_patches_the_pinned_archive(tmp_path):
    upstream = require_upstream(Path(os.environ.get("SLAMRUN_SHARED", ROOT.parent / "shared")) / "upstream")
    opts = native.NativeOptions(sources_dir=upstream, into=tmp_path / "tree")
    tree = native.unpack_only(opts, "dpvo", log=lambda m: None)
    assert tree == tmp_path / "tree" / SOURCES["dpvo"].top and (tree / "dpvo" / "_scatter.py").is_file()
    with pytest.raises(native.NativeBuildError, match="is not empty"):
        native.unpack_only(opts, "dpvo", log=lambda m: None)


def problems(build, weights):
    return gpu_native_problems(build, weights, "dpvo", "dpvo.pth")
