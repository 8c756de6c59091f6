"""The GPU path on a machine without a GPU: a method that needs one is a spec error before any run (validate, plan,
campaign); the NVML sampling's logic with a stand-in NVML (the issue allows a stand-in for the logic; a real GPU runs
scripts/gpu-check.sh), carried into resources.csv and results.csv by a real campaign; and scripts/gpu-check.sh up to
its first step that needs the GPU machine, in a fresh venv that has only what that machine has plus the carried
wheels."""

from __future__ import annotations

import csv
import importlib.metadata as md
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import psutil
import pytest
import yaml

from slamrun.backends.local import LocalBackend
from slamrun.backends.monitor import Gpu, host_gpus
from slamrun.engine.campaign import run_campaign
from slamrun.engine.spec_file import load_spec, validate_spec
from slamrun.errors import SpecError

ROOT = Path(__file__).resolve().parents[1]
NO_GPU = "needs a GPU; this host has none"


@pytest.fixture(scope="module")
def gpu_less():
    if host_gpus():
        pytest.skip(reason="this host has a GPU: these tests are about one without")


def slamrun(*args, env=None, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "slamrun.cli", *map(str, args)], capture_output=True, text=True, env=env, cwd=cwd
    )


def spec_file(folder: Path, methods: list[dict], backend: str = "local", **extra) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    spec = {
        "name": "g",
        "results": str(folder / "results"),
        "cache": str(folder / "cache"),
        "datasets": [
            {
                "name": "synth",
                "path": str(folder / "data"),
                "sequences": ["room"],
                "synthetic": {"frames": 40, "seed": 0, "size": "320x240"},
            }
        ],
        "methods": methods,
        "directions": ["forward"],
        "trials": 1,
        "backend": backend,
        **extra,
    }
    path = folder / "spec.yaml"
    path.write_text(yaml.safe_dump(spec))
    return path


# ---------------------------------------------------------------- gpu: true on a host without a GPU


@pytest.mark.parametrize(
    ("backend", "method"),
    [
        ("local", {"name": "dpvo"}),
        ("docker", {"name": "dpvo"}),
        ("local", {"name": "droid_slam"}),
        ("docker", {"name": "droid_slam"}),
        ("local", {"name": "mast3r_slam"}),
        ("docker", {"name": "mast3r_slam"}),
        ("docker", {"name": "cnn_svo", "params": {"gpu": True}}),
    ],
)
def test_a_method_that_needs_a_gpu_is_refused_before_any_run(tmp_path, gpu_less, backend, method):
    spec = spec_file(tmp_path, [method, {"name": "reference_vo"}], backend)
    for command in ("validate", "plan", "campaign"):
        res = slamrun(command, spec)
        assert res.returncode == 1, (command, res.stdout, res.stderr)
        assert re.search(rf"line \d+: methods\[0\]: {method['name']} {NO_GPU}", res.stderr), (command, res.stderr)
        assert "methods[1]" not in res.stderr  # reference_vo runs on the CPU
    assert not (tmp_path / "results").exists() and not (tmp_path / "data").exists()  # nothing ran, nothing generated


def test_the_same_spec_without_gpu_is_accepted(tmp_path, gpu_less):
    spec = spec_file(tmp_path, [{"name": "cnn_svo", "params": {"gpu": False}}], "docker")
    res = slamrun("validate", spec)
    assert NO_GPU not in res.stderr, res.stderr


def fake_smi(folder: Path, output: str, code: int = 0) -> Path:
    folder.mkdir(exist_ok=True)
    smi = folder / "nvidia-smi"
    smi.write_text(f"#!/bin/sh\ncat <<'EOF'\n{output}\nEOF\nexit {code}\n")
    smi.chmod(0o755)
    return smi


def test_host_detection_asks_nvidia_smi_when_nvml_does_not_answer(tmp_path, gpu_less):
    h100 = "GPU 0: NVIDIA H100 80GB HBM3 (UUID: GPU-0d4c8a4e-1111-2222-3333-444455556666)"
    assert host_gpus(smi=str(fake_smi(tmp_path / "a", h100))) == [h100]
    broken = "NVIDIA-SMI has failed because it couldn't communicate with the NVIDIA driver."
    assert host_gpus(smi=str(fake_smi(tmp_path / "b", broken, 9))) == []  # present but not answering
    assert host_gpus(smi=str(tmp_path / "absent")) == []
    # through the command line: a host whose nvidia-smi answers passes the check
    spec = spec_file(tmp_path / "c", [{"name": "cnn_svo", "params": {"gpu": True}}], "docker")
    env = {**os.environ, "PATH": f"{fake_smi(tmp_path / 'd', h100).parent}{os.pathsep}{os.environ['PATH']}"}
    res = slamrun("validate", spec, env=env)
    assert NO_GPU not in res.stderr, res.stderr


def test_no_check_where_other_machines_run_the_runs(tmp_path, gpu_less):
    raw = yaml.safe_load(spec_file(tmp_path, [{"name": "cnn_svo", "params": {"gpu": True}}], "docker").read_text())
    raw["distributed"] = {"cluster": "slurm", "walltime": "12:00:00"}
    validate_spec(raw, tmp_path, check_files=False)  # the cluster's workers run them
    raw["distributed"] = {"address": "local"}  # Dask workers on this machine: checked
    with pytest.raises(SpecError, match=NO_GPU):
        validate_spec(raw, tmp_path, check_files=False)
    del raw["distributed"]
    validate_spec(raw, tmp_path, check_files=False, check_gpu=False)  # reading a campaign (import), not running it


# ---------------------------------------------------------------- NVML sampling, with a stand-in NVML


class NVMLError(Exception):
    def __init__(self, value: int):
        super().__init__(f"NVML error {value}")
        self.value = value


class FakeNvml:
    """The part of pynvml that slamrun.backends.monitor.Gpu calls, over a list of devices; a device's `samples` is a
    list of (pid, timestamp_us, sm %) or an NVML error code; `procs(handle)` may be replaced by a callable."""

    NVMLError = NVMLError
    NVML_ERROR_NOT_SUPPORTED = 3
    NVML_ERROR_NOT_FOUND = 6

    def __init__(self, devices: list[dict]):
        self.devices = devices

    def nvmlInit(self):
        pass

    def nvmlDeviceGetCount(self):
        return len(self.devices)

    def nvmlDeviceGetHandleByIndex(self, i):
        return self.devices[i]

    def nvmlDeviceGetName(self, h):
        return h.get("name", "Fake GPU")

    def _procs(self, entries):
        if isinstance(entries, int):
            raise NVMLError(entries)
        entries = entries() if callable(entries) else entries
        return [SimpleNamespace(pid=pid, usedGpuMemory=mem) for pid, mem in entries]

    def nvmlDeviceGetComputeRunningProcesses(self, h):
        return self._procs(h.get("compute", []))

    def nvmlDeviceGetGraphicsRunningProcesses(self, h):
        return self._procs(h.get("graphics", []))

    def nvmlDeviceGetProcessUtilization(self, h, since_us):
        samples = h.get("samples", [])
        if isinstance(samples, int):
            raise NVMLError(samples)
        samples = samples() if callable(samples) else samples
        found = [SimpleNamespace(pid=p, timeStamp=t, smUtil=u) for p, t, u in samples if t >= since_us]
        if not found:
            raise NVMLError(self.NVML_ERROR_NOT_FOUND)
        return found

    def nvmlDeviceGetUtilizationRates(self, h):
        return SimpleNamespace(gpu=h.get("util", 0))


MB = 2**20


def now_us(ago_s: float = 0.0) -> int:
    return int((time.time() - ago_s) * 1e6)


def test_memory_is_the_runs_processes_on_every_device_each_once():
    run, other = {101, 102}, 999
    nvml = FakeNvml(
        [
            {"compute": [(101, 300 * MB), (other, 500 * MB)], "graphics": [(101, 300 * MB), (102, None)]},
            {"compute": [(102, 100 * MB)]},
        ]
    )
    mem, _ = Gpu(nvml).sample(run)
    assert mem == pytest.approx(400.0)


def test_utilisation_is_the_runs_newest_samples_on_the_busiest_device():
    nvml = FakeNvml(
        [
            {"compute": [(7, MB)], "samples": [(7, now_us(0.6), 20), (7, now_us(0.2), 35), (8, now_us(0.1), 60)]},
            {"compute": [(9, MB)], "samples": [(9, now_us(0.1), 10), (7, now_us(5.0), 90)]},  # 90: too old
        ]
    )
    assert Gpu(nvml).sample({7, 9}) == (pytest.approx(2.0), 35.0)


def test_a_device_without_per_process_accounting_counts_only_where_the_run_holds_memory():
    nvml = FakeNvml(
        [
            {"compute": [(5, 200 * MB)], "samples": FakeNvml.NVML_ERROR_NOT_SUPPORTED, "util": 77},
            {"compute": [(6, 200 * MB)], "samples": FakeNvml.NVML_ERROR_NOT_SUPPORTED, "util": 95},  # not the run's
        ]
    )
    assert Gpu(nvml).sample({5}) == (pytest.approx(200.0), 77.0)
    assert Gpu(nvml).sample({42}) == (0.0, 0.0)  # a run on the CPU beside a busy GPU used none of it


def test_no_sample_in_the_window_is_zero_and_failing_queries_stop_nothing():
    nvml = FakeNvml([{"compute": 999, "graphics": [(3, 50 * MB)], "samples": []}])  # 999: an unknown NVML error
    assert Gpu(nvml).sample({3}) == (pytest.approx(50.0), 0.0)


def test_without_nvml_the_gpu_columns_stay_empty(gpu_less):
    gpu = Gpu()  # the real pynvml where installed: no driver here
    assert not gpu.available and gpu.sample({os.getpid()}) == (None, None)


def test_a_campaign_carries_the_sampled_gpu_columns_into_results_csv(tmp_path):
    """A real campaign (reference_vo on a synthetic room, the local backend) whose backend's NVML (a stand-in) sees
    the run's own processes, as NVML sees a process on the GPU: 256 MB and 40 % per process."""

    def children() -> list[tuple[int, int]]:
        return [(p.pid, 256 * MB) for p in psutil.Process().children(recursive=True)]

    def samples() -> list[tuple[int, int, int]]:
        return [(pid, now_us(0.05), 40) for pid, _ in children()]

    backend = LocalBackend(sample_interval_s=0.1)
    backend.gpu = Gpu(FakeNvml([{"compute": children, "samples": samples}]))
    spec = load_spec(spec_file(tmp_path, [{"name": "reference_vo"}], "local", report=False))
    res = run_campaign(spec, backend=backend, log=lambda *a: None)
    rows = list(csv.DictReader(open(res.results_csv)))
    assert len(rows) == 1 and rows[0]["failure"] != "infra", rows  # done, or lost on this small room: a result
    assert float(rows[0]["gpu_mem_peak_mb"]) == pytest.approx(256.0)
    assert 0 < float(rows[0]["gpu_util_mean_pct"]) <= 40.0
    series = list(csv.DictReader(open(next(res.results.rglob("resources.csv")))))
    assert any(s["gpu_mem_mb"] == "256.0" and s["gpu_util_pct"] == "40.0" for s in series)


# ---------------------------------------------------------------- scripts/gpu-check.sh, up to its GPU steps

# what the GPU machine has (issue 41's brief; pip, and setuptools as PyTorch requires it on Python 3.12): their
# installed closure is seen by the fresh venv, nothing else
MACHINE = "numpy scipy pandas pyarrow opencv-python-headless matplotlib psutil rich pyyaml requests pip".split()
MACHINE.append("setuptools")


def closure(names: list[str]) -> set[str]:
    """The installed distributions `names` need (their requirements, recursively, as installed here)."""
    seen: set[str] = set()
    todo = list(names)
    while todo:
        name = re.split(r"[ ;<>=!~\[(]", todo.pop(), maxsplit=1)[0].lower().replace("_", "-")
        if name in seen:
            continue
        try:
            dist = md.distribution(name)
        except md.PackageNotFoundError:
            continue
        seen.add(name)
        todo += [r for r in dist.requires or [] if "extra ==" not in r]
    return seen


def machine_site(dest: Path) -> Path:
    """A folder holding links to the top-level files of the machine's packages (and their metadata)."""
    dest.mkdir()
    for name in closure(MACHINE):
        dist = md.distribution(name)
        for f in dist.files or []:
            top = Path(f.parts[0])
            src = Path(dist.locate_file(top))
            if top.name != ".." and src.exists() and not (dest / top).exists() and not top.name.endswith(".pth"):
                (dest / top).symlink_to(src)
    return dest


@pytest.fixture(scope="module")
def wheels(tmp_path_factory) -> Path:
    """The carried folder, made by scripts/gpu-wheels.sh for this Python's version (the GPU machine's is 3.12)."""
    folder = tmp_path_factory.mktemp("whl")
    ver = f"{sys.version_info.major}.{sys.version_info.minor}"
    shared = Path(os.environ.get("SLAMRUN_SHARED", ROOT.parent / "shared")) / "upstream"
    if not any(shared.glob("DPVO-*.tar.gz")):
        pytest.skip(reason=f"no DPVO archive in {shared}: the pinned sources live in shared/upstream beside the repo")
    env = {**os.environ, "PY": sys.executable, "SOURCES": str(shared)}
    res = subprocess.run(
        ["bash", "scripts/gpu-wheels.sh", str(folder), ver], cwd=ROOT, env=env, capture_output=True, text=True
    )
    if (
        res.returncode != 0
        and "pip" in res.stderr
        and re.search(r"No matching distribution|connection", res.stderr, re.I)
    ):
        pytest.skip(reason=f"no package index reachable for the wheels: {res.stderr.strip()[-200:]}")
    assert res.returncode == 0, res.stderr
    return folder


def test_gpu_wheels_are_few_small_and_complete(wheels):
    names = sorted(p.name.split("-")[0].lower() for p in wheels.glob("*.whl"))
    assert names == [
        "annotated_types", "faiss_cpu", "natsort", "ninja", "plyfile", "pydantic", "pydantic_core", "setuptools",
        "typing_extensions", "typing_inspection",
    ]  # fmt: skip
    assert (wheels / "eigen3-headers.tar.gz").is_file() and (wheels / "sources").is_dir()
    archives = sorted(p.name.split("-")[0] for p in (wheels / "sources").iterdir())
    assert archives == ["DPVO", "DROID", "MASt3R", "lietorch"]
    # 64 MiB travel with the working tree (5 MB): MASt3R-SLAM's archive (15 MB) and faiss (18 MB) are most of it
    assert sum(p.stat().st_size for p in wheels.rglob("*") if p.is_file()) < 54 * 2**20
    sums = (wheels / "SHA256SUMS").read_text()
    assert all(p.name in sums for p in wheels.glob("*.whl"))


def test_gpu_check_until_its_gpu_steps_in_a_fresh_venv(tmp_path, wheels):
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)  # pip: the machine's
    site = next(venv.glob("lib/python3*/site-packages"))
    (site / "machine.pth").write_text(f"{machine_site(tmp_path / 'machine')}\n")
    python = venv / "bin" / "python"
    lacks = subprocess.run([python, "-c", "import pydantic"], capture_output=True, text=True)
    assert lacks.returncode != 0  # the machine has no pydantic: the carried wheels bring it
    out, work = tmp_path / "out", tmp_path / "work"
    env = {**os.environ, "PYTHON": str(python), "WHEELS": str(wheels), "WORK": str(work), "FRAMES": "40"}
    tree = tmp_path / "tree"  # the working tree as copied to the machine (the install writes into it)
    shutil.copytree(
        ROOT, tree, ignore=shutil.ignore_patterns(".venv", ".git", ".whl", "*.egg-info", "__pycache__", "*.so")
    )
    res = subprocess.run(
        ["bash", "scripts/gpu-check.sh", str(out), "--until-gpu"], cwd=tree, env=env, capture_output=True, text=True
    )
    assert res.returncode == 0, res.stdout + res.stderr
    steps = re.findall(r"^\[\d\d:\d\d:\d\d \+\s*\d+s\] step (\w+):", res.stdout, re.M)
    assert steps == ["preflight", "install", "eigen", "synth", "unpack"], res.stdout
    assert "stopped before the GPU steps" in res.stdout
    check = "import pydantic, slamrun.methods; print(pydantic.__file__); print(slamrun.__file__)"
    where = subprocess.run([python, "-c", check], capture_output=True, text=True, cwd=tmp_path).stdout.split()
    assert where[0].startswith(str(venv)) and where[1].startswith(str(tree))  # the wheel's pydantic, the tree's slamrun
    assert len(list(zip_names(work / "data" / "room" / "images.zip"))) == 40
    patched = next((work / "dpvo-patched").glob("DPVO-*"))
    assert (patched / "dpvo" / "_scatter.py").is_file() and "EIGEN_INCLUDE_DIR" in (patched / "setup.py").read_text()
    assert (work / "eigen3" / "Eigen" / "Core").is_file() or Path("/usr/include/eigen3/Eigen/Core").is_file()
    for step in steps:
        assert (out / "logs" / f"{step}.log").is_file()
    res = subprocess.run(
        ["bash", "scripts/gpu-check.sh", str(tmp_path / "out-droid"), "--until-gpu"],
        cwd=tree, env={**env, "METHOD": "droid_slam"}, capture_output=True, text=True,
    )  # fmt: skip
    assert res.returncode == 0, res.stdout + res.stderr
    droid = next((work / "droid_slam-patched").glob("DROID-SLAM-*"))
    assert (droid / "thirdparty" / "lietorch" / "setup.py").is_file() and (droid / "droid_slam" / "droid.py").is_file()
    # both methods: the setup once, then both builds side by side, which need the GPU machine's PyTorch
    all_out = str(tmp_path / "out-all")
    both = ["bash", "scripts/gpu-check-all.sh", all_out]
    res = subprocess.run(both, cwd=tree, env=env, capture_output=True, text=True)
    assert res.returncode == 1 and "stopped before the GPU steps" in res.stdout, res.stdout + res.stderr
    for method in ("dpvo", "droid_slam", "mast3r_slam"):  # every method with a native build
        assert f"FAILED: the build of {method}; its log {all_out}/build-{method}.log" in res.stdout
    assert res.stdout.count("cannot import PyTorch") == 3 and "step campaign" not in res.stdout
    empty = tmp_path / "empty"
    empty.mkdir()
    res = subprocess.run(
        ["bash", "scripts/gpu-check.sh", str(tmp_path / "out2"), "--until-gpu"],
        cwd=tree, env={**env, "WHEELS": str(empty)}, capture_output=True, text=True,
    )  # fmt: skip
    assert res.returncode == 1 and "FAILED at step 'preflight'" in res.stdout and "make gpu-wheels" in res.stdout


def zip_names(path: Path):
    import zipfile

    with zipfile.ZipFile(path) as z:
        yield from (n for n in z.namelist() if not n.endswith("/"))


def test_summary_is_one_page_from_what_the_script_leaves(tmp_path):
    from slamrun.engine.export import COLUMNS

    row = dict.fromkeys(COLUMNS, "")
    rows = [
        row | {"method": "dpvo-standin", "direction": d, "trial": "0", "status": "done", "n_poses": "80",
               "wall_s": "12.5", "fps": "12.8", "gpu_mem_peak_mb": "1830.0", "gpu_util_mean_pct": "41.5"}
        for d in ("forward", "backward")
    ]  # fmt: skip
    with open(tmp_path / "results.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(COLUMNS))
        w.writeheader()
        w.writerows(rows)
    (tmp_path / "runs" / "dpvo-standin_room_forward_0").mkdir(parents=True)
    (tmp_path / "runs" / "dpvo-standin_room_forward_0" / "log.txt").write_text(
        "dpvo: 80 poses (31 keyframes) in 1.40 s (57.1 fps); PyTorch's peak allocation 1500 MB\n"
    )
    res = subprocess.run([sys.executable, "scripts/gpu_check_summary.py", str(tmp_path), "300"], cwd=ROOT)
    assert res.returncode == 0
    text = (tmp_path / "summary.txt").read_text()
    assert "runs: 2 (2 done)" in text and "GPU memory peak 1830.0 MB, GPU utilisation 41.5 %" in text
    assert "(57.1 fps)" in text and len(text.splitlines()) < 60


# ---------------------------------------------------------------- podman: the GPU through CDI, podman 5.4 or later


def fake_podman(folder: Path, version: str) -> Path:
    folder.mkdir(exist_ok=True)
    podman = folder / "podman"
    podman.write_text(f"#!/bin/sh\necho 'podman version {version}'\n")
    podman.chmod(0o755)
    return folder


@pytest.mark.parametrize(("version", "refused"), [("4.3.1", True), ("5.3.2", True), ("5.4.0", False), ("6.0.1", False)])
def test_podman_before_5_4_is_refused_for_a_gpu_method_before_any_run(tmp_path, version, refused):
    h100 = "GPU 0: NVIDIA H100 80GB HBM3 (UUID: GPU-0d4c8a4e-1111-2222-3333-444455556666)"
    path = [fake_smi(tmp_path / "smi", h100).parent, fake_podman(tmp_path / "podman", version)]
    env = {**os.environ, "PATH": os.pathsep.join([*map(str, path), os.environ["PATH"]])}
    spec = spec_file(tmp_path / "s", [{"name": "cnn_svo", "params": {"gpu": True}}, {"name": "dso"}], "podman")
    res = slamrun("validate", spec, env=env)
    assert NO_GPU not in res.stderr, res.stderr
    said = f"methods[0]: cnn_svo needs podman 5.4 or later to give a container the GPU (this is podman {version}"
    assert (said in res.stderr) is refused, res.stderr
    if refused:
        assert "nvidia-ctk cdi generate" in res.stderr and "backend: docker" in res.stderr
    assert "methods[1]: dso needs podman" not in res.stderr  # a CPU method runs on any podman


def test_the_gpu_request_is_the_engines_own():
    import docker

    from slamrun.backends.docker import DockerBackend
    from slamrun.backends.podman import PodmanBackend

    (nvidia,) = DockerBackend.gpu_requests()  # Docker: the nvidia runtime's `gpu` capability, every GPU
    assert nvidia == docker.types.DeviceRequest(count=-1, capabilities=[["gpu"]])
    (cdi,) = PodmanBackend.gpu_requests()  # podman's API ignores that one; from 5.4 it honours a CDI request
    assert cdi["Driver"] == "cdi" and cdi["DeviceIDs"] == ["nvidia.com/gpu=all"]
