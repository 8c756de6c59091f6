"""DROID-SLAM's image (slamrun/methods/droid_slam/image): its recipe against DPVO's (the same torch stage word for
word, so one list of
pins and one set of cached layers), the compiler left out of the runtime stage, the native route's patches and
stand-in reused, its labels and its refusal without a network; and, when the image slamrun/droid_slam has been
built, inside it without a GPU: the compiled extensions and DROID's modules import, lietorch's SE3 inverse on a known
camera (the convention slamrun's process relies on), the torch_scatter stand-in against pytorch_scatter's own code,
and slamrun's DROID-SLAM process on a prepared view up to the missing GPU."""

from __future__ import annotations

import json
import re
import subprocess
import tarfile
from pathlib import Path

import numpy as np
import pytest

from slamrun.errors import SlamRunError
from slamrun.images import native
from slamrun.images import sources as src
from slamrun.images.build import ARCH_ARG, BuildOptions, model_choice, pypi_files_of, recipe_text, toolchain_labels
from tests import images
from tests.conftest import UPSTREAM, recipe, require_upstream
from tests.test_dpvo_image import stages

ROOT = Path(__file__).resolve().parents[1]
RECIPE = recipe("droid_slam")
DOCKERFILE = RECIPE / "Dockerfile"
DPVO = recipe("dpvo") / "Dockerfile"
IMAGE = "slamrun/droid_slam:latest"
ARCHS = "7.5 8.0 8.6 8.9 9.0"
TOOLCHAIN = {"nvidia-cuda-nvcc", "nvidia-cuda-crt", "nvidia-nvvm", "nvidia-cuda-cccl", "ninja"}


def instructions(text: str) -> list[str]:
    """A recipe's instructions, comments left out, continued lines joined."""
    joined = re.sub(r"\\\n", " ", "\n".join(ln for ln in text.splitlines() if not ln.lstrip().startswith("#")))
    return [ln for ln in joined.splitlines() if ln.strip()]


# ---------------------------------------------------------------- the recipe


def test_the_torch_stages_are_dpvos():
    """The build starts from the torch-cuda stage and ends on torch-runtime, DPVO's (recipes/torch_cuda): the same
    wheels (one pinned list, DPVO_TORCH and DPVO_TOOLCHAIN), the same steps, so that an engine that built one serves
    the other from its cache."""
    mine, theirs = stages(recipe_text(DOCKERFILE)), stages(recipe_text(DPVO))
    assert (
        [instructions(s) for s in mine[:3]] == [instructions(s) for s in theirs[:3]]
        and mine[3].startswith("FROM torch-cuda AS build")
        and mine[4].startswith("FROM torch-runtime\n")
    )
    assert pypi_files_of(DOCKERFILE) == pypi_files_of(DPVO)
    tables = (src.DPVO_TORCH, src.DPVO_TOOLCHAIN, src.DPVO_LOOP_CLOSURE)
    assert [f.filename for table in tables for f in src.pypi_table(table)] == (pypi_files_of(DOCKERFILE))
    assert not (RECIPE / "requirements.txt").exists()  # no second copy of the pins


def test_the_runtime_stage_holds_no_compiler_and_the_build_reuses_the_native_recipe():
    _, venv, runtime_base, build, runtime = stages(recipe_text(DOCKERFILE))
    uninstalled = re.search(r"pip uninstall -y --no-cache-dir \\\n\s+([^\\\n]+)", venv).group(1).split()
    assert set(uninstalled) == TOOLCHAIN
    assert "pip uninstall -y --no-cache-dir triton" in venv
    assert "pypi" not in runtime and "g++" not in runtime and "sources/" not in runtime
    assert "! ls /opt/venv/lib/python3.11/site-packages/nvidia/cu13/bin/nvcc" in runtime_base
    assert (
        "check_image.py" in runtime
        and "USER slam" in runtime
        and "useradd --create-home --uid 1000 slam" in runtime_base
    )
    assert ARCH_ARG.search(build).group(1) == ARCHS
    assert "COPY sources/droid_slam.tar.gz sources/lietorch.tar.gz" in build  # pytorch_scatter is not built
    recipe = native.NATIVE["droid_slam"]
    assert recipe.patches == RECIPE / "patches.py" and recipe.standin == RECIPE / "standin_model.py"
    assert recipe.parts == (("lietorch", "thirdparty/lietorch"),)
    assert "method/image/patches.py" in build
    assert "COPY recipes/torch_cuda/torch_scatter_compat.py /opt/slamrun-build/docker/torch_cuda/" in build
    script = (RECIPE / "network.sh").read_text()
    seed, flow = re.search(r"seed=(\d+) flow_px=(\d+)", script).groups()
    assert recipe.standin_args == (seed, str(float(flow)))
    # the process runs with the GPU family's helpers, both copied in, the process in the folder named by the method
    assert "COPY methods/gpu_process.py /opt/slamrun/slamrun/methods/" in runtime
    assert "COPY method/process.py /opt/slamrun/slamrun/methods/${METHOD}/" in runtime


def test_the_build_scripts_place_lietorch_as_the_native_build_does_and_parse():
    script = (RECIPE / "build-extensions.sh").read_text()
    assert 'tar -xzf "$lietorch" -C "$tree/thirdparty"' in script
    assert 'mv "$tree"/thirdparty/lietorch-* "$tree/thirdparty/lietorch"' in script
    for folder, exts in native.NATIVE["droid_slam"].setups:
        where = '"$tree"' if folder == "." else f'"$tree/{folder}"'
        assert f'bash "$compile" {where} "$arch" "$jobs" {" ".join(exts)}' in script
    common = (recipe("common") / "build-torch-extension.sh").read_text()
    assert 'CUDA_HOME=$cuda TORCH_CUDA_ARCH_LIST="$arch"' in common and "libcudart.so.13" in common
    for path in (
        RECIPE / "build-extensions.sh",
        RECIPE / "network.sh",
        ROOT / "slamrun/methods/recipes/common/build-torch-extension.sh",
    ):
        res = subprocess.run(["bash", "-n", str(path)], capture_output=True, text=True)
        assert res.returncode == 0, (path, res.stderr)


def test_labels_name_torch_cuda_and_the_targets():
    labels = toolchain_labels(DOCKERFILE, pypi_files_of(DOCKERFILE), {})
    assert labels == {
        "slamrun.torch": "2.11.0",
        "slamrun.cuda": "13.0 (cuda-toolkit 13.0.2, nvcc 13.0.88)",
        "slamrun.cuda-arch": ARCHS,
    }


def test_weights_are_given_standin_or_an_error_naming_droid_pth_and_where_it_is_published(tmp_path):
    assert model_choice("droid_slam", BuildOptions(weights={"droid.pth": tmp_path / "x"}))[0] == "given"
    kind, detail = model_choice("droid_slam", BuildOptions(standin_model=True))
    assert kind == "standin" and "NOT the trained network" in detail
    with pytest.raises(SlamRunError, match=r"droid_slam needs droid.pth.*--weights droid.pth=FILE.*download_model.sh"):
        model_choice("droid_slam", BuildOptions())


# ---------------------------------------------------------------- inside the built image (no GPU)


def built_image():
    return images.built_image(IMAGE, "slamrun images --method droid_slam --standin-model, about an hour")


def run_in_image(api, command: list[str], volumes: dict | None = None, timeout: int = 600) -> tuple[int, str]:
    return images.run_in_image(api, IMAGE, command, volumes, timeout)


IMPORTS = """
import json, sys
record = json.load(open('/opt/droid_slam/build.json'))
tree = '/opt/droid_slam/' + record['tree']
sys.path[:0] = [tree + '/thirdparty/lietorch', tree + '/droid_slam', tree]
import torch
import droid_backends, lietorch_backends, lietorch
from droid import Droid
from droid_net import DroidNet
net = DroidNet()
net.load_state_dict(torch.load('/opt/droid_slam/' + record['weights_file'], map_location='cpu', weights_only=True))
print(json.dumps({'torch': torch.__version__, 'cuda': torch.version.cuda, 'gpu': torch.cuda.is_available(),
                  'ext': [m.__file__ for m in (droid_backends, lietorch_backends)],
                  'mods': sorted(m for m in ('matplotlib', 'scipy', 'open3d', 'torch_scatter') if m in sys.modules),
                  'params': sum(p.numel() for p in net.parameters()), 'record': record}))
"""


def test_the_compiled_extensions_and_droid_import_inside_the_image_without_a_gpu():
    api, labels = built_image()
    status, out = run_in_image(api, ["python3", "-c", IMPORTS])
    assert status == 0, out[-3000:]
    got = json.loads(out.strip().splitlines()[-1])
    assert got["torch"].startswith(labels["slamrun.torch"]) and got["cuda"] == labels["slamrun.cuda"].split()[0]
    assert got["gpu"] is False and got["mods"] == []  # headless: none of the patched-out packages was imported
    tree = f"/opt/droid_slam/{got['record']['tree']}/"
    droid_ext, lie_ext = got["ext"]
    assert droid_ext.startswith(f"{tree}droid_backends.") and droid_ext.endswith(".so")
    assert lie_ext.startswith(f"{tree}thirdparty/lietorch/lietorch_backends.") and lie_ext.endswith(".so")
    assert got["params"] > 4_000_000  # DroidNet: two encoders and the update operator
    assert got["record"]["arch"] == labels["slamrun.cuda-arch"]
    label = json.loads(labels["slamrun.weights"])["droid.pth"]
    if got["record"]["weights"].startswith("untrained stand-in"):
        assert "NOT the trained network" in label and "NOT the trained network" in got["record"]["weights"]
    else:
        assert label.split(" sha256 ")[-1] in got["record"]["weights"]
    commits = {s: f"{src.SOURCES[s].repo}@{src.SOURCES[s].commit}" for s in ("droid_slam", "lietorch")}
    assert json.loads(labels["slamrun.sources"]) == commits
    status, out = run_in_image(
        api, ["sh", "-c", "id -u; ls /opt/venv/lib/python3.11/site-packages/nvidia/cu13/bin 2>&1"]
    )
    assert out.split()[0] == "1000" and "nvcc" not in out
    status, out = run_in_image(api, ["python3", "-c", "import importlib.util as u; print(u.find_spec('triton'))"])
    assert status == 0 and out.split()[-1] == "None", out


CONVENTION = """
import json, sys
record = json.load(open('/opt/droid_slam/build.json'))
sys.path.insert(0, '/opt/droid_slam/' + record['tree'] + '/thirdparty/lietorch')
import torch, lietorch
w2c = torch.tensor(json.loads(sys.argv[1]), dtype=torch.float64)
print(json.dumps(lietorch.SE3(w2c).inv().data.tolist()))
"""


def test_lietorchs_inverse_of_world_to_camera_poses_gives_the_cameras_in_the_world():
    """DROID keeps world-to-camera poses and terminate() returns .inv() of them: on known cameras (centre c, rotation
    R), lietorch's inverse (its compiled CPU code, in the image) of [-R^T c, q(R^T)] is [c, q(R)], scalar last."""
    from scipy.spatial.transform import Rotation

    api, _ = built_image()
    rng = np.random.default_rng(4)
    rot = Rotation.random(5, random_state=7)
    centres = rng.normal(0, 2, (5, 3))
    w2c = np.column_stack([-rot.inv().apply(centres), rot.inv().as_quat()])
    status, out = run_in_image(api, ["python3", "-c", CONVENTION, json.dumps(w2c.tolist())])
    assert status == 0, out[-3000:]
    c2w = np.array(json.loads(out.strip().splitlines()[-1]))
    np.testing.assert_allclose(c2w[:, :3], centres, atol=1e-9)
    q = c2w[:, 3:] * np.sign(c2w[:, 6:7] * rot.as_quat()[:, 3:4])  # q and -q are one rotation
    np.testing.assert_allclose(q, rot.as_quat(), atol=1e-9)


SCATTER = """
import sys, torch
ns = {}
exec(open('/ref/utils.py').read(), ns)
exec(open('/ref/scatter.py').read().replace('from .utils import broadcast', ''), ns)  # torch.ops: in bodies only
import json
record = json.load(open('/opt/droid_slam/build.json'))
sys.path.insert(0, '/opt/droid_slam/' + record['tree'] + '/droid_slam')
import _scatter
g = torch.Generator().manual_seed(1)
src = torch.randn(1, 9, 3, 4, generator=g, dtype=torch.float64)
index = torch.tensor([4, 0, 4, 1, 1, 0, 3, 4, 0])
for kw in ({'dim': 1}, {'dim': 1, 'dim_size': 7}, {'dim': -3}):
    assert torch.equal(_scatter.scatter_mean(src, index, **kw), ns['scatter_mean'](src, index, **kw)), kw
    assert torch.equal(_scatter.scatter_sum(src, index, **kw), ns['scatter_sum'](src, index, **kw)), kw
ints = torch.arange(9)
assert torch.equal(_scatter.scatter_mean(ints, index, dim=0), ns['scatter_mean'](ints, index, dim=0))
print('same')
"""


def test_the_torch_scatter_stand_in_matches_pytorch_scatters_own_code(tmp_path):
    """droid_net's scatter_mean and geom/ba.py's scatter_sum, as the image holds them, against pytorch_scatter's
    torch_scatter/scatter.py from its pinned archive (pure Python there), on the image's PyTorch."""
    api, _ = built_image()
    archive = require_upstream(UPSTREAM / src.SOURCES["pytorch_scatter"].filename)
    ref = tmp_path / "ref"
    ref.mkdir()
    with tarfile.open(archive) as tar:
        for name in ("utils.py", "scatter.py"):
            member = f"{src.SOURCES['pytorch_scatter'].top}/torch_scatter/{name}"
            (ref / name).write_bytes(tar.extractfile(member).read())
    ref.chmod(0o755)
    status, out = run_in_image(api, ["python3", "-c", SCATTER], {ref: "/ref"})
    assert status == 0 and out.split()[-1] == "same", out[-3000:]


def test_slamruns_droid_slam_process_in_the_image_reads_a_view_and_stops_at_the_missing_gpu(tmp_path):
    """The image's `python3 -m slamrun.methods.droid_slam.process`, as the docker backend runs it, on a real prepared
    view (every parameter set to a value other than its default, as one JSON object): it reads the settings, the frames
    and the network, imports PyTorch and exits 3 saying there is no GPU; a setting it does not know exits 1, named."""
    from slamrun.datasets.cache import prepare
    from slamrun.datasets.make_synthetic import generate
    from slamrun.datasets.view import Direction, Profile
    from slamrun.methods.droid_slam import DroidSlam, DroidSlamParams
    from tests.test_dpvo import changed

    api, _ = built_image()
    view = prepare(generate(tmp_path / "room", frames=20, seed=3), Direction.forward, Profile.rectified, tmp_path / "c")
    argv = DroidSlam(changed(DroidSlamParams)).for_backend("docker").command(view.at("/data"), Path("/tmp"))
    status, out = run_in_image(api, argv, {view.root: "/data"})
    assert status == 3 and "NO GPU" in out, out[-3000:]
    argv[argv.index("--settings") + 1] = '{"strides": 3}'  # a setting the process does not know: bad input, named
    status, out = run_in_image(api, argv, {view.root: "/data"})
    assert status == 1 and "droid_slam: unknown setting 'strides'" in out, out[-3000:]
