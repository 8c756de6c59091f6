"""Native builds of the GPU methods, for machines without a container engine: `slamrun native-build dpvo|droid_slam`.

A method's CUDA extensions (DPVO's cuda_corr, cuda_ba, lietorch_backends; DROID-SLAM's lietorch_backends and
droid_backends) are compiled once into slamrun's cache ($XDG_CACHE_HOME/slamrun/native/<method>, the method module's
default_build) from the pinned archives (slamrun/images/sources.py; DROID-SLAM's lietorch unpacked into its submodule
folder) with the same patches as the image (slamrun/methods/<method>/image/patches.py), by and for the Python that runs
slamrun: its PyTorch (a CUDA build), the CUDA toolkit of $CUDA_HOME or of the nvcc on PATH, Eigen 3.4's headers
(Debian's libeigen3-dev, or a folder given), for one GPU architecture (the local GPU's by default), with all cores. The
build folder is staged and renamed into place at the end, so a failed build never replaces a working one. It holds the
patched tree with the extensions beside it, the network (given, or an untrained stand-in), build.log and build.json
(what it is). NATIVE holds each method's recipe (its declaration's native_build); one code path builds them all."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tarfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import slamrun.methods
from slamrun.errors import SlamRunError
from slamrun.images import sources as src
from slamrun.images.build import ROOT, BuildOptions, _weights_file, model_choice, weights_of
from slamrun.methods.declare import NativeMethod, declared
from slamrun.methods.native_gpu import native_build_folder

DEFAULT_CUDA = "/usr/local/cuda"
EIGEN_CANDIDATES = ("/usr/include/eigen3", "/usr/local/include/eigen3")
TAIL_LINES = 30


class NativeBuildError(SlamRunError):
    """A native build cannot start (no PyTorch with CUDA, no nvcc, no Eigen, no GPU to build for) or failed."""


NATIVE: dict[str, NativeMethod] = {  # each method's native_build, from its folder's declaration
    name: recipe for name, cls in slamrun.methods.REGISTRY.items() if (recipe := declared(cls, "native_build"))
}


def native_method(name: str) -> NativeMethod:
    try:
        return NATIVE[name]
    except KeyError:
        raise NativeBuildError(f"no native build for {name!r} (known: {', '.join(NATIVE)})") from None


@dataclass
class NativeOptions:
    sources_dir: Path | None = None  # the pinned archive from here (no network)
    source_url: str | None = None
    source_cache: Path | None = None
    arch: str | None = None  # compute capability, e.g. 9.0; default: the local GPU's
    jobs: int = field(default_factory=lambda: os.cpu_count() or 2)
    eigen: Path | None = None  # a folder holding Eigen/Core
    weights: dict[str, Path] = field(default_factory=dict)  # dpvo.pth or droid.pth -> file or URL#sha256=HEX
    standin_model: bool = False
    into: Path | None = None  # the build folder (default: slamrun's cache)
    python: str = sys.executable


def eigen_dir(given: Path | None) -> Path:
    """A folder with Eigen 3's headers (Eigen/Core): the one given, $EIGEN_INCLUDE_DIR, or a system one."""
    candidates = [given] if given else [os.environ.get("EIGEN_INCLUDE_DIR"), *EIGEN_CANDIDATES]
    for c in filter(None, candidates):
        if (Path(c) / "Eigen" / "Core").is_file():
            return Path(c).resolve()
    where = f"{given} holds no Eigen/Core" if given else f"none in $EIGEN_INCLUDE_DIR or {', '.join(EIGEN_CANDIDATES)}"
    raise NativeBuildError(
        f"the GPU methods' extensions need Eigen 3.4's headers, {where}: install Debian's libeigen3-dev, or give "
        "--eigen DIR (a folder holding Eigen/Core)"
    )


def cuda_home() -> Path:
    """The CUDA toolkit: $CUDA_HOME, else the one of the nvcc on PATH, else /usr/local/cuda (as PyTorch looks)."""
    if home := os.environ.get("CUDA_HOME") or os.environ.get("CUDA_PATH"):
        if (Path(home) / "bin" / "nvcc").is_file():
            return Path(home)
        raise NativeBuildError(f"CUDA_HOME={home} holds no bin/nvcc: point it at the CUDA toolkit")
    if nvcc := shutil.which("nvcc"):
        return Path(nvcc).resolve().parent.parent
    if Path(DEFAULT_CUDA, "bin", "nvcc").is_file():
        return Path(DEFAULT_CUDA)
    raise NativeBuildError(
        f"no nvcc on PATH, in $CUDA_HOME or in {DEFAULT_CUDA}: the GPU methods' extensions need the CUDA compiler"
    )


def local_arch() -> str:
    """The compute capability of this machine's first GPU (nvidia-smi), e.g. 9.0."""
    try:
        out = subprocess.run(
            ["nvidia-smi", "--query-gpu=compute_cap", "--format=csv,noheader"],
            capture_output=True,
            text=True,
            timeout=30,
        )
    except (OSError, subprocess.TimeoutExpired):
        out = None
    caps = out.stdout.split() if out is not None and out.returncode == 0 else []
    if not caps:
        raise NativeBuildError("no GPU answers here (nvidia-smi): give the target with --arch (9.0: H100/H200)")
    return caps[0]


def torch_info(python: str, label: str = "DPVO") -> dict:
    """PyTorch's version and CUDA version in `python` (a subprocess: importing it takes seconds)."""
    # torch_dist: the installed distribution's version, as slamrun.methods.dpvo reads it without importing torch
    code = (
        "import json, torch, importlib.metadata as md; print(json.dumps({'torch': torch.__version__, "
        "'torch_dist': md.version('torch'), 'cuda': torch.version.cuda}))"
    )
    res = subprocess.run([python, "-c", code], capture_output=True, text=True)
    if res.returncode != 0:
        raise NativeBuildError(f"{python} cannot import PyTorch: {_last_line(res.stderr)}; install a CUDA build of it")
    info = json.loads(res.stdout.strip().splitlines()[-1])
    if not info["cuda"]:
        raise NativeBuildError(f"PyTorch {info['torch']} in {python} is a CPU build: {label} needs a CUDA build")
    return info


def build(name: str, opts: NativeOptions, log: Callable[[str], None] = print) -> dict:
    """Compile method `name` natively into `opts.into` (default: slamrun's cache); returns its build record."""
    m = native_method(name)
    t0 = time.monotonic()
    final = Path(opts.into or native_build_folder(name))
    model, _ = model_choice(name, BuildOptions(weights=opts.weights, standin_model=opts.standin_model))
    info = torch_info(opts.python, m.label)
    env = build_environment(opts, log)
    archives = obtain_archives(m, opts)
    sources = [f"{src.SOURCES[s].repo}@{src.SOURCES[s].commit}" for s in archives]
    log(f"sources {', '.join(sources)}; PyTorch {info['torch']} (CUDA {info['cuda']})")
    stage = final.with_name(f"{final.name}.staging-{os.getpid()}")
    shutil.rmtree(stage, ignore_errors=True)
    stage.mkdir(parents=True)
    try:
        tree = unpack_and_patch(m, archives, stage, log)
        compile_extensions(m, opts.python, tree, env, stage / "build.log", log)
        weights = place_weights(m, opts, model, tree, stage, log, weights_of(name).companions)
        record = {
            "method": name,
            "source": sources[0],
            **({"parts": dict(zip([p for _, p in m.parts], sources[1:], strict=True))} if m.parts else {}),
            "patches": f"{m.patches.relative_to(ROOT)} sha256 {src.file_sha256(m.patches)}",
            "tree": tree.name,
            "python": opts.python,
            **info,
            "arch": env["TORCH_CUDA_ARCH_LIST"],
            "cuda_home": env["CUDA_HOME"],
            "eigen": env["EIGEN_INCLUDE_DIR"],
            "weights_file": f"weights/{m.weights_name}",
            "weights": weights,
            "seconds": round(time.monotonic() - t0, 1),
            "finished": time.time(),
        }
        (stage / "build.json").write_text(json.dumps(record, indent=1) + "\n")
        replace_folder(stage, final)
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        raise
    log(f"built {name} in {record['seconds']:.0f} s into {final} (for compute capability {record['arch']})")
    return record


def unpack_only(opts: NativeOptions, name: str, log: Callable[[str], None] = print) -> Path:
    """The checked archives unpacked and patched into `opts.into` (or the cache's build folder), nothing compiled: to
    read or check the patched tree on a machine without the toolkit. Returns the tree."""
    m = native_method(name)
    dest = Path(opts.into or native_build_folder(name))
    if dest.exists() and any(dest.iterdir()):
        raise NativeBuildError(f"{dest} is not empty: give an empty or new folder with --into")
    archives = obtain_archives(m, opts)
    dest.mkdir(parents=True, exist_ok=True)
    tree = unpack_and_patch(m, archives, dest, log)
    log(f"unpacked and patched into {tree} (not compiled)")
    return tree


def obtain_archives(m: NativeMethod, opts: NativeOptions) -> dict[str, Path]:
    """The method's checked archives, its own first: source name -> file."""
    names = [m.source, *(s for s, _ in m.parts)]
    return {s: src.obtain(s, opts.sources_dir, opts.source_cache, opts.source_url) for s in names}


def build_environment(opts: NativeOptions, log: Callable[[str], None]) -> dict[str, str]:
    """The compiler's environment: the toolkit, the target, the jobs, Eigen."""
    home = cuda_home()
    arch = opts.arch or local_arch()
    eigen = eigen_dir(opts.eigen)
    log(f"CUDA toolkit {home}, target compute capability {arch}, {opts.jobs} jobs, Eigen {eigen}")
    return {
        **os.environ,
        "CUDA_HOME": str(home),
        "TORCH_CUDA_ARCH_LIST": arch,
        "MAX_JOBS": str(opts.jobs),
        "EIGEN_INCLUDE_DIR": str(eigen),
        # nvcc, and the tools of the Python's own environment (ninja, which PyTorch runs for a parallel build)
        "PATH": os.pathsep.join([str(home / "bin"), str(Path(opts.python).parent), os.environ.get("PATH", "")]),
    }


def unpack_and_patch(m: NativeMethod, archives: dict[str, Path], dest: Path, log: Callable[[str], None]) -> Path:
    """The method's archive unpacked into `dest`, each part's into its (empty) submodule folder, then patched
    (slamrun/methods/<method>/image/patches.py); returns the tree."""
    with tarfile.open(archives[m.source], "r:gz") as tar:
        tar.extractall(dest, filter="data")
    tree = dest / src.SOURCES[m.source].top
    for part, folder in m.parts:
        target = tree / folder
        if target.exists() and any(target.iterdir()):
            raise NativeBuildError(f"{target}: not the empty submodule folder {src.SOURCES[part].repo} belongs in")
        target.mkdir(parents=True, exist_ok=True)
        target.rmdir()
        with tarfile.open(archives[part], "r:gz") as tar:
            tar.extractall(target.parent, filter="data")
        os.rename(target.parent / src.SOURCES[part].top, target)
    res = subprocess.run([sys.executable, str(m.patches), str(tree)], capture_output=True, text=True)
    if res.returncode != 0:
        raise NativeBuildError(f"{m.patches} failed on {tree}: {_last_line(res.stderr)}")
    log(f"patched {tree.name}: {len(res.stdout.splitlines())} edits")
    return tree


def compile_extensions(
    m: NativeMethod, python: str, tree: Path, env: dict, log_path: Path, log: Callable[[str], None]
) -> None:
    """`setup.py build_ext --inplace` in each of the method's setup folders (their output in log_path), then an
    import of all the extensions."""
    log(f"compiling {', '.join(m.extensions)} (log: {log_path})")
    with open(log_path, "w") as out:
        for folder, _ in m.setups:
            res = subprocess.run(
                [python, "setup.py", "build_ext", "--inplace"],
                cwd=tree / folder,
                env=env,
                stdout=out,
                stderr=subprocess.STDOUT,
            )
            if res.returncode != 0:
                out.flush()
                raise NativeBuildError(
                    f"compiling {m.label} ({folder}) failed (exit {res.returncode}); the end of {log_path}:\n"
                    f"{_tail(log_path)}"
                )
    check = f"import torch, {', '.join(m.extensions)}"
    path = os.pathsep.join(str((tree / p).resolve()) for p in m.import_path)
    res = subprocess.run(
        [python, "-c", check], cwd=tree, env={**env, "PYTHONPATH": path}, capture_output=True, text=True
    )
    if res.returncode != 0:
        raise NativeBuildError(f"{m.label}'s extensions were built but do not import: {_last_line(res.stderr)}")


def place_weights(
    m: NativeMethod,
    opts: NativeOptions,
    model: str,
    tree: Path,
    stage: Path,
    log: Callable[[str], None],
    companions: tuple[str, ...] = (),
) -> str:
    """The network into stage/weights/<name> (the files given with it beside it, by their names): the files given, or
    an untrained stand-in (its script makes the companions too); returns what it is."""
    dest = stage / "weights" / m.weights_name
    dest.parent.mkdir()
    if model == "given":
        notes = []
        for name in (m.weights_name, *companions):  # the network, then the files given with it
            given = _weights_file(name, str(opts.weights[name]), BuildOptions(source_cache=opts.source_cache))
            shutil.copyfile(given, dest.parent / name)
            notes.append(f"{name}: {given.name} sha256 {src.file_sha256(dest.parent / name)}")
        note = "; ".join(notes)
    else:
        said = standin_network(opts.python, tree, dest, m)
        note = (
            f"untrained stand-in with {m.weights_name}'s interface ({m.standin_note.format(out=said)}, sha256 "
            f"{src.file_sha256(dest)}): plumbing only, NOT the trained network, accuracy meaningless"
        )
    log(f"network: {note}")
    return note


def standin_network(python: str, tree: Path, dest: Path, m: NativeMethod) -> str:
    """The method's network with random weights from a fixed seed, its flow head scaled (slamrun/methods/<method>/image/
    standin_model.py, as the image makes it; needs the compiled extensions, not a GPU); returns the script's last line
    (what it applied, where it says)."""
    argv = [python, str(m.standin), str(tree), str(dest), *m.standin_args]
    res = subprocess.run(argv, capture_output=True, text=True)
    if res.returncode != 0:
        raise NativeBuildError(f"the stand-in network could not be made: {_last_line(res.stderr)}")
    return _last_line(res.stdout)


def replace_folder(stage: Path, final: Path) -> None:
    """`stage` becomes `final`; an earlier build there is removed only once the new one is in place."""
    old = final.with_name(f"{final.name}.old-{os.getpid()}")
    if final.exists():
        os.rename(final, old)
    os.rename(stage, final)
    shutil.rmtree(old, ignore_errors=True)


def _tail(path: Path, lines: int = TAIL_LINES) -> str:
    return "\n".join(path.read_text(errors="replace").splitlines()[-lines:])


def _last_line(text: str) -> str:
    lines = [line for line in text.strip().splitlines() if line.strip()]
    return lines[-1] if lines else "(no output)"
