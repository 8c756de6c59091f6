"""DPVO's image (slamrun/methods/dpvo/image): its recipe against the pins (every PyPI file by SHA-256, one CUDA version
for PyTorch
and the compiler, the compiler left out of the runtime stage, the native route's patches and stand-in reused), the
labels `slamrun images` gives it, its refusal without a network before any download, and, when the image
slamrun/dpvo has been built, its compiled extensions and DPVO's package imported inside it without a GPU."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from slamrun.images import native
from slamrun.images import sources as src
from slamrun.images.build import ARCH_ARG, BuildOptions, model_choice, pypi_files_of, recipe_text, toolchain_labels
from tests import images
from tests.conftest import UPSTREAM, recipe, require_upstream

ROOT = Path(__file__).resolve().parents[1]
RECIPE = recipe("dpvo")
DOCKERFILE = RECIPE / "Dockerfile"
TORCH_CUDA = recipe("torch_cuda")  # the stages DPVO's and DROID-SLAM's images share
IMAGE = "slamrun/dpvo:latest"
ARCHS = "7.5 8.0 8.6 8.9 9.0"  # Turing, A100, Ampere consumer, Ada, Hopper (issue 41)
TOOLCHAIN = {"nvidia-cuda-nvcc", "nvidia-cuda-crt", "nvidia-nvvm", "nvidia-cuda-cccl"}
HASHED = re.compile(r"^([a-z0-9-]+)==([^ ]+) --hash=sha256:([0-9a-f]{64})$")


def pins(path: Path) -> list[str]:
    return [line for line in path.read_text().splitlines() if line and not line.startswith("#")]


def stages(text: str) -> list[str]:
    """The recipe's stages, each from its FROM line."""
    return ["FROM" + part for part in re.split(r"^FROM", text, flags=re.MULTILINE)[1:]]


# ---------------------------------------------------------------- the recipe and its pins


def test_every_file_the_recipe_installs_is_pinned_by_hash_and_generated_from_the_table():
    torch_files, tool_files = src.pypi_table(src.DPVO_TORCH), src.pypi_table(src.DPVO_TOOLCHAIN)
    loop_files = src.pypi_table(src.DPVO_LOOP_CLOSURE)  # DPV-SLAM's (tests/test_dpv_slam.py)
    assert pypi_files_of(DOCKERFILE) == [f.filename for f in (*torch_files, *tool_files, *loop_files)]
    assert all(src.PYPI_FILES[f.filename] == f for f in (*torch_files, *tool_files))
    for name, table in (("requirements.txt", torch_files), ("requirements-build.txt", tool_files)):
        lines = pins(TORCH_CUDA / name)
        assert "\n".join(lines) + "\n" == src.requirements(list(table)), name
        for line, f in zip(lines, table, strict=True):
            m = HASHED.match(line)
            assert m and m.groups() == (f.project, f.version, f.sha256), line
    projects = [f.project for f in (*torch_files, *tool_files)]
    assert len(projects) == len(set(projects))  # one file per project
    assert {f.project for f in tool_files} == TOOLCHAIN | {"ninja"}
    text = recipe_text(DOCKERFILE)
    installs = [i for i in re.sub(r"\\\n", " ", text).splitlines() if "pip install" in i]
    assert len(installs) == 3 and all("--no-index" in i for i in installs)  # runtime, compiler, loop closure
    assert all(i.count("--require-hashes") == 1 for i in installs if "-r /opt" in i)


def test_pytorch_and_the_compiler_are_one_cuda_version():
    files = {f.project: f for f in (*src.pypi_table(src.DPVO_TORCH), *src.pypi_table(src.DPVO_TOOLCHAIN))}
    cuda = ".".join(files["cuda-toolkit"].version.split(".")[:2])
    assert cuda == "13.0" and files["torch"].version == "2.11.0"
    for project in (*TOOLCHAIN, "nvidia-cuda-runtime", "nvidia-cuda-nvrtc", "nvidia-nvjitlink", "nvidia-cuda-cupti"):
        assert files[project].version.startswith(cuda + "."), (project, files[project].version)
    assert not [p for p in files if p.endswith("-cu12")]  # no library of another CUDA major version
    assert "cp311" in files["torch"].filename  # Debian 12's Python


def test_the_toolchain_is_what_cuda_toolkit_pins_when_its_wheel_is_at_hand():
    """cuda-toolkit 13.0.2's own metadata (independent of this project's table) names the compiler's versions."""
    f = src.PYPI_FILES[next(n for n in src.PYPI_FILES if n.startswith("cuda_toolkit-"))]
    wheel = src.default_cache() / f.filename
    if not wheel.is_file():
        pytest.skip(reason=f"{wheel} not fetched (slamrun images --method dpvo fetches it)")
    assert src.file_sha256(wheel) == f.sha256
    with zipfile.ZipFile(wheel) as zf:
        meta = zf.read(next(n for n in zf.namelist() if n.endswith(".dist-info/METADATA"))).decode()
    extras = "nvcc|crt|nvvm|cccl|cudart"
    pinned = dict(re.findall(rf"Requires-Dist: ([a-z-]+)==([\d.]+)\.\*; .*extra == '(?:{extras})'", meta))
    table = {f.project: f.version for f in src.pypi_table(src.DPVO_TORCH + src.DPVO_TOOLCHAIN)}
    assert set(pinned) == TOOLCHAIN | {"nvidia-cuda-runtime"}
    assert all(table[p] == v for p, v in pinned.items()), (pinned, table)


def test_the_runtime_stage_holds_no_compiler_and_the_build_reuses_the_native_patches():
    torch_cuda, venv, runtime_base, build, runtime = stages(recipe_text(DOCKERFILE))
    assert torch_cuda.startswith("FROM debian:bookworm-slim AS torch-cuda") and build.startswith(
        "FROM torch-cuda AS build"
    )
    assert venv.startswith("FROM torch-cuda AS torch-venv") and runtime_base.startswith("FROM debian:bookworm-slim AS")
    assert runtime.startswith("FROM torch-runtime\n")
    uninstalled = re.search(r"pip uninstall -y --no-cache-dir \\\n\s+([^\\\n]+)", venv).group(1).split()
    assert set(uninstalled) == TOOLCHAIN | {"ninja"}  # every build-only wheel is removed before the copy
    assert "pip uninstall -y --no-cache-dir triton" in venv  # torch.compile's, not DPVO's
    assert "COPY --from=torch-venv /opt/venv /opt/venv" in runtime_base and "--from=build /opt/venv" not in runtime
    for stage in (runtime_base, runtime):
        assert "pypi" not in stage and "g++" not in stage and "sources/" not in stage
    assert "! ls /opt/venv/lib/python3.11/site-packages/nvidia/cu13/bin/nvcc" in runtime_base
    assert "USER slam" in runtime and "useradd --create-home --uid 1000 slam" in runtime_base
    assert ARCH_ARG.search(build).group(1) == ARCHS
    # the native route's files, not copies: patches.py (with the torch_scatter stand-in) and the stand-in network
    recipe_ = native.NATIVE["dpvo"]
    assert recipe_.patches == RECIPE / "patches.py" and recipe_.standin == RECIPE / "standin_model.py"
    assert "method/image/patches.py method/image/build-extensions.sh" in re.sub(r"\\\n\s*", "", build)
    assert "COPY recipes/torch_cuda/torch_scatter_compat.py /opt/slamrun-build/docker/torch_cuda/" in build
    assert "method/image/standin_model.py" in build
    script = (RECIPE / "network.sh").read_text()
    seed, gain = re.search(r"seed=(\d+) gain=(\d+)", script).groups()
    assert recipe_.standin_args == (seed, str(float(gain)))


def test_the_shared_stages_are_one_text_put_ahead_of_each_recipe_that_names_them():
    """DPVO's and DROID-SLAM's recipes start FROM torch-cuda and end FROM torch-runtime, which neither defines: the
    build puts recipes/torch_cuda/stages.Dockerfile ahead of each (once), so both build the same steps; a recipe
    naming no shared stage is built as written."""
    shared = (TORCH_CUDA / "stages.Dockerfile").read_text()
    for name in ("dpvo", "droid_slam", "mast3r_slam"):
        own = (recipe(name) / "Dockerfile").read_text()
        assert "FROM debian" not in own  # its base is the shared stage's
        if name != "mast3r_slam":  # MASt3R-SLAM installs its own pins on top (tests/test_mast3r_slam.py)
            assert "pip install" not in own and "pypi/" not in own  # all of it shared
        assert recipe_text(recipe(name) / "Dockerfile") == shared + "\n" + own
    for name in ("reference_vo", "dynaslam"):
        assert recipe_text(recipe(name) / "Dockerfile") == (recipe(name) / "Dockerfile").read_text()
    listed = subprocess.run([sys.executable, "-m", "slamrun.cli", "images", "--list"], capture_output=True, text=True)
    line = "dpvo: slamrun/dpvo:latest <- dpvo/image/Dockerfile (+ recipes/torch_cuda/stages.Dockerfile)"
    assert line in listed.stdout
    stages = "recipes/debian/stages.Dockerfile, recipes/pangolin/stages.Dockerfile"
    assert f"dso: slamrun/dso:latest <- dso/image/Dockerfile (+ {stages})\n" in listed.stdout
    assert "reference_vo: slamrun/reference_vo:latest <- reference_vo/image/Dockerfile\n" in listed.stdout


def test_the_extension_build_script_compiles_with_the_wheels_toolkit_for_the_given_targets():
    script = (RECIPE / "build-extensions.sh").read_text()
    common = (recipe("common") / "build-torch-extension.sh").read_text()
    assert 'CUDA_HOME=$cuda TORCH_CUDA_ARCH_LIST="$arch"' in common and "cuda=$site/nvidia/cu13" in common
    assert "libcudart.so.13" in common and 'python3 "$patches" "$tree"' in script
    assert 'bash "$compile" "$tree" "$arch" "$jobs" cuda_corr cuda_ba lietorch_backends' in script
    assert 'compile=$(dirname "$0")/../common/build-torch-extension.sh' in script  # copied beside the recipe's:
    copies = re.sub(r"\\\n", " ", DOCKERFILE.read_text())
    assert re.search(
        r"COPY [^\n]*recipes/common/build-torch-extension.sh[^\n]* /opt/slamrun-build/docker/common/",
        copies,
    )
    assert re.search(r"COPY [^\n]*method/image/build-extensions.sh[^\n]* /opt/slamrun-build/docker/dpvo/", copies)
    assert native.NATIVE["dpvo"].setups == ((".", ("cuda_corr", "cuda_ba", "lietorch_backends")),)
    res = subprocess.run(["bash", "-n", str(RECIPE / "build-extensions.sh")], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    res = subprocess.run(["bash", "-n", str(RECIPE / "network.sh")], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr


# ---------------------------------------------------------------- what `slamrun images` says of it


def test_labels_name_torch_cuda_and_the_targets():
    wheels = pypi_files_of(DOCKERFILE)
    labels = toolchain_labels(DOCKERFILE, wheels, {})
    assert labels == {
        "slamrun.torch": "2.11.0",
        "slamrun.cuda": "13.0 (cuda-toolkit 13.0.2, nvcc 13.0.88)",
        "slamrun.cuda-arch": ARCHS,
    }
    assert toolchain_labels(DOCKERFILE, wheels, {"TORCH_CUDA_ARCH_LIST": "9.0"})["slamrun.cuda-arch"] == "9.0"
    reference = recipe("reference_vo") / "Dockerfile"
    assert toolchain_labels(reference, pypi_files_of(reference), {}) == {}  # not a GPU image


def test_the_context_of_a_standin_build_is_labelled_with_what_it_holds(tmp_path):
    """The build context `slamrun images --method dpvo --standin-model` assembles (the real archive, the fetched
    wheels, when this machine's download cache holds them): its labels say what the image will hold."""
    from slamrun.images.build import assemble_context

    missing = [f for f in pypi_files_of(DOCKERFILE) if not (src.default_cache() / f).is_file()]
    if missing:
        pytest.skip(reason=f"{len(missing)} wheels not in {src.default_cache()} (slamrun images --method dpvo fetches)")
    opts = BuildOptions(sources_dir=require_upstream(), standin_model=True, build_args={"TORCH_CUDA_ARCH_LIST": "9.0"})
    (tmp_path / "ctx").mkdir()
    labels = assemble_context("dpvo", DOCKERFILE, opts, tmp_path / "ctx", lambda line: None)
    assert "NOT the trained network" in json.loads(labels["slamrun.weights"])["dpvo.pth"]
    assert json.loads(labels["slamrun.build-args"]) == {
        "VOCABULARY": "none",
        "DPVO_MODEL": "standin",
        "TORCH_CUDA_ARCH_LIST": "9.0",
    }
    assert labels["slamrun.torch"] == "2.11.0" and labels["slamrun.cuda-arch"] == "9.0"
    assert set(json.loads(labels["slamrun.pypi"])) == set(pypi_files_of(DOCKERFILE))
    assert (tmp_path / "ctx" / "sources" / "dpvo.tar.gz").is_file()
    assert sorted(p.name for p in (tmp_path / "ctx" / "pypi").iterdir()) == sorted(pypi_files_of(DOCKERFILE))


def test_weights_choice_is_given_standin_or_an_error_naming_the_file(tmp_path):
    assert model_choice("dpvo", BuildOptions(weights={"dpvo.pth": tmp_path / "x"}))[0] == "given"
    kind, detail = model_choice("dpvo", BuildOptions(standin_model=True))
    assert kind == "standin" and "NOT the trained network" in detail


def test_images_without_a_network_stop_before_fetching_anything(tmp_path):
    """`slamrun images --method dpvo` with neither --weights nor --standin-model: one line naming dpvo.pth and where
    it is published, before 2.6 GB of wheels are fetched (here from a PyPI address that answers nothing)."""
    from slamrun.backends.docker import DockerBackend
    from slamrun.errors import InfraError

    try:
        DockerBackend().client.api.version()
    except (InfraError, Exception) as exc:  # noqa: BLE001 - `slamrun images` needs an engine to start at all
        pytest.skip(reason=f"no Docker engine: {exc}")
    sources = tmp_path / "sources"
    sources.mkdir()
    archive = require_upstream(UPSTREAM / src.SOURCES["dpvo"].filename)
    os.symlink(archive, sources / archive.name)
    env = {**os.environ, "XDG_CACHE_HOME": str(tmp_path / "cache"), "SLAMRUN_PYPI_URL": "http://127.0.0.1:9"}
    argv = [sys.executable, "-m", "slamrun.cli", "images", "--method", "dpvo", "--sources", str(sources)]
    res = subprocess.run([*argv, "--log-dir", str(tmp_path / "logs")], capture_output=True, text=True, env=env)
    assert res.returncode != 0
    assert "dpvo needs dpvo.pth" in res.stderr and "models.zip" in res.stderr and "--standin-model" in res.stderr
    assert "Traceback" not in res.stderr and "cannot find" not in res.stderr
    assert not (tmp_path / "cache" / "slamrun" / "sources").exists()  # nothing fetched


# ---------------------------------------------------------------- inside the built image (no GPU)


def built_image():
    return images.built_image(IMAGE, "slamrun images --method dpvo --standin-model; CI builds DSO's only")


def run_in_image(api, command: list[str], volumes: dict | None = None, timeout: int = 600) -> tuple[int, str]:
    return images.run_in_image(api, IMAGE, command, volumes, timeout)


IMPORTS = """
import json, sys
record = json.load(open('/opt/dpvo/build.json'))
sys.path.insert(0, '/opt/dpvo/' + record['tree'])
import torch
import cuda_corr, cuda_ba, lietorch_backends, dpvo
from dpvo.net import VONet
import dpvo.lietorch, dpvo.altcorr, dpvo.fastba
print(json.dumps({'torch': torch.__version__, 'cuda': torch.version.cuda, 'gpu': torch.cuda.is_available(),
                  'ext': [m.__file__ for m in (cuda_corr, cuda_ba, lietorch_backends)], 'record': record}))
"""


def test_the_compiled_extensions_and_dpvo_import_inside_the_image_without_a_gpu():
    api, labels = built_image()
    status, out = run_in_image(api, ["python3", "-c", IMPORTS])
    assert status == 0, out[-3000:]
    got = json.loads(out.strip().splitlines()[-1])
    assert got["torch"].startswith(labels["slamrun.torch"]) and got["cuda"] == labels["slamrun.cuda"].split()[0]
    assert got["gpu"] is False  # no GPU given: nothing above touched CUDA
    assert all(f.startswith(f"/opt/dpvo/{got['record']['tree']}/") and f.endswith(".so") for f in got["ext"])
    assert got["record"]["arch"] == labels["slamrun.cuda-arch"]
    label = json.loads(labels["slamrun.weights"])["dpvo.pth"]  # what `slamrun images` chose, said in the image too
    standin = got["record"]["weights"].startswith("untrained stand-in")
    if standin:
        assert "NOT the trained network" in label and "NOT the trained network" in got["record"]["weights"]
    else:  # the given file's SHA-256
        assert label.split(" sha256 ")[-1] in got["record"]["weights"]
    assert json.loads(labels["slamrun.sources"]) == {"dpvo": f"princeton-vl/DPVO@{src.SOURCES['dpvo'].commit}"}
    status, out = run_in_image(
        api, ["sh", "-c", "id -u; ls /opt/venv/lib/python3.11/site-packages/nvidia/cu13/bin 2>&1"]
    )
    assert out.split()[0] == "1000"  # the image's user, not root
    assert "nvcc" not in out  # the compiler stayed in the build stage
    status, out = run_in_image(api, ["python3", "-c", "import importlib.util as u; print(u.find_spec('triton'))"])
    assert status == 0 and out.split()[-1] == "None", out  # torch.compile's compiler left out (641 MB)


def test_slamruns_dpvo_process_in_the_image_reads_a_view_and_stops_at_the_missing_gpu(tmp_path):
    """The image's `python3 -m slamrun.methods.dpvo.process`, as the docker backend runs it (every parameter set to a
    value other than its default, handed as one JSON object), on a real prepared view: it reads the settings, the
    frames and the network, imports PyTorch, and exits 3 saying there is no GPU; a setting it does not know is bad
    input (exit 1), named."""
    from slamrun.datasets.cache import prepare
    from slamrun.datasets.make_synthetic import generate
    from slamrun.datasets.view import Direction, Profile
    from slamrun.methods.dpvo import Dpvo, DpvoParams
    from tests.test_dpvo import changed

    api, _ = built_image()
    view = prepare(generate(tmp_path / "room", frames=20, seed=3), Direction.forward, Profile.rectified, tmp_path / "c")
    params = changed(DpvoParams)
    assert params["loop_closure"] is True  # DPV-SLAM's: its modules are in the image, so no refusal before the GPU
    argv = Dpvo(params).for_backend("docker").command(view.at("/data"), Path("/tmp"))
    status, out = run_in_image(api, argv, {view.root: "/data"})
    assert status == 3 and "NO GPU" in out and "needs numba" not in out, out[-3000:]
    argv[argv.index("--settings") + 1] = '{"patch_count": 3}'
    status, out = run_in_image(api, argv, {view.root: "/data"})
    assert status == 1 and "dpvo: unknown setting 'patch_count'" in out, out[-3000:]
