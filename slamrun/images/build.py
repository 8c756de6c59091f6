"""Build the methods' Docker images: `slamrun images` / `make images [METHOD=name] [SOURCES=DIR]`.

Each image is built from `slamrun/methods/<name>/image/Dockerfile` in a build context the runner assembles: the
method's own folder as `method/` (never another method's: a copy of a folder builds from its own recipe and patches),
the shared recipe parts as `recipes/`, the modules families share (`slamrun/methods/*.py`) as `methods/`, the upstream
sources the Dockerfile copies (`COPY sources/<source>.tar.gz ...`, checked archives from a folder or GitHub, see
slamrun/images/sources.py) and the inputs a build needs (`inputs/`: a vocabulary, weights, frames to train a
vocabulary on). Build arguments (MARCH, JOBS, VOCABULARY, any --build-arg) reach the Dockerfile. The image carries
labels saying what it holds (sources and commits, vocabulary, weights, target). Every build writes its log to
`<log_dir>/<name>.log` and a record (`<name>.json`: time, size, labels); a failed build names the step and
shows the end of its output.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import tempfile
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path

import slamrun.methods
from slamrun.errors import InfraError, SlamRunError
from slamrun.images import sources as src
from slamrun.methods.declare import Vocabulary, Weights, declared

ROOT = Path(__file__).resolve().parents[2]
METHODS = Path(slamrun.methods.__file__).parent  # each method's folder: its adapter, its image/ recipe
DEFAULT_LOG_DIR = ROOT / ".cache" / "images"
SOURCE_RE = re.compile(r"\bsources/([A-Za-z0-9_.+-]+)\.tar\.gz\b")
PYPI_RE = re.compile(r"\bpypi/([A-Za-z0-9_.+-]+\.(?:whl|tar\.gz|zip))(?![A-Za-z0-9_.+-])")  # wheels and sdists
LABEL = "slamrun"
METHOD_ARG = re.compile(r"^ARG METHOD\s*$", re.MULTILINE)  # the build argument that gives a recipe its method's name
ANSI = re.compile(r"\x1b\[[0-9;]*m")  # the builder colours a step's stderr


def vocabulary_of(name: str) -> Vocabulary | None:
    """The vocabulary method `name` declares (its folder's declaration), if any."""
    cls = slamrun.methods.REGISTRY.get(name)
    return declared(cls, "vocabulary") if cls else None


def weights_of(name: str) -> Weights | None:
    """The trained network method `name` declares, if any."""
    cls = slamrun.methods.REGISTRY.get(name)
    return declared(cls, "network") if cls else None


@dataclass
class BuildOptions:
    sources_dir: Path | None = None  # take source archives from here (no network)
    source_url: str | None = None  # GitHub or a mirror of its archive addresses
    source_cache: Path | None = None  # where downloaded archives are kept
    march: str = "x86-64-v2"
    jobs: int = field(default_factory=lambda: os.cpu_count() or 2)
    vocabulary: dict[str, Path] = field(default_factory=dict)  # method (or "*") -> file
    weights: dict[str, Path] = field(default_factory=dict)  # weight name -> file
    train_vocabulary: bool = True  # train a small vocabulary when neither the source nor the user has one
    standin_model: bool = False  # an untrained stand-in network when no weights are given (plumbing only)
    build_args: dict[str, str] = field(default_factory=dict)
    log_dir: Path = DEFAULT_LOG_DIR
    no_cache: bool = False  # rebuild every step (to measure a build from scratch)


@dataclass
class BuildRecord:
    method: str
    tag: str
    seconds: float
    size_mb: float
    log: str
    labels: dict[str, str]
    finished: float
    image_id: str = ""  # the image the build made (a rebuild with every step cached makes the same one)


def buildable() -> dict[str, tuple[str, Path]]:
    """Registered methods with an image: name → (tag, Dockerfile)."""
    out = {}
    for name, cls in sorted(slamrun.methods.REGISTRY.items()):
        dockerfile = cls.recipe()
        if cls.native and not dockerfile.exists():  # runs natively; its image's recipe is not written yet
            continue
        if isinstance(cls.image, str):  # `external` names its image per spec (a property), not built here
            out[name] = (cls.image, dockerfile)
    return out


FROM_RE = re.compile(r"^FROM\s+(\S+)(?:\s+AS\s+(\S+))?", re.MULTILINE | re.IGNORECASE)


def shared_stages() -> dict[str, Path]:
    """The build stages recipes share: stage name -> the `recipes/<part>/stages.Dockerfile` that defines it."""
    out = {}
    for path in sorted((METHODS / "recipes").glob("*/stages.Dockerfile")):
        out |= {stage.lower(): path for _, stage in FROM_RE.findall(path.read_text()) if stage}
    return out


def stage_files(dockerfile: Path) -> list[Path]:
    """The shared stage files a recipe starts FROM (naming one of their stages that it does not define itself), with
    the files those stages start FROM in turn, each ahead of the files that need it."""
    shared, parts = shared_stages(), []

    def need(text: str) -> None:
        defined = {stage.lower() for _, stage in FROM_RE.findall(text) if stage}
        for base, _ in FROM_RE.findall(text):
            path = shared.get(base.lower())
            if path is not None and base.lower() not in defined and path not in parts:
                need(path.read_text())
                parts.append(path)

    need(dockerfile.read_text())
    return parts


def recipe_text(dockerfile: Path) -> str:
    """The Dockerfile as built: the shared stage files it starts FROM ahead of its own text; one Dockerfile, so Docker
    builds the shared stages as any other and caches their layers once for every image that names them."""
    return "".join(part.read_text() + "\n" for part in stage_files(dockerfile)) + dockerfile.read_text()


def pypi_files_of(dockerfile: Path) -> list[str]:
    """The PyPI files a Dockerfile (with the shared stages it names) copies from the build context (`pypi/<file>`)."""
    names = []
    instructions = re.sub(r"\\\n", " ", recipe_text(dockerfile))  # a continued line is one instruction
    for line in instructions.splitlines():
        if line.strip().upper().startswith(("COPY", "ADD")):
            names += [n for n in PYPI_RE.findall(line) if n not in names]
    return names


ARCH_ARG = re.compile(r'^ARG\s+TORCH_CUDA_ARCH_LIST=(?:"([^"]*)"|(\S*))', re.MULTILINE)


def toolchain_labels(dockerfile: Path, wheels: list[str], build_args: dict[str, str]) -> dict[str, str]:
    """What a GPU image is compiled with ({} for the others): PyTorch's version and CUDA's (from the PyPI files it
    copies: torch, cuda-toolkit, nvidia-cuda-nvcc) and the compute capabilities (TORCH_CUDA_ARCH_LIST: the build
    argument given, else the recipe's default)."""
    versions = {src.PYPI_FILES[w].project: src.PYPI_FILES[w].version for w in wheels}
    if "torch" not in versions:
        return {}
    labels = {f"{LABEL}.torch": versions["torch"]}
    if "cuda-toolkit" in versions:
        toolkit = versions["cuda-toolkit"]
        nvcc = f", nvcc {versions['nvidia-cuda-nvcc']}" if "nvidia-cuda-nvcc" in versions else ""
        labels[f"{LABEL}.cuda"] = f"{'.'.join(toolkit.split('.')[:2])} (cuda-toolkit {toolkit}{nvcc})"
    m = ARCH_ARG.search(recipe_text(dockerfile))
    arch = build_args.get("TORCH_CUDA_ARCH_LIST") or (m and (m.group(1) or m.group(2)))
    if arch:
        labels[f"{LABEL}.cuda-arch"] = arch
    return labels


def model_choice(name: str, opts: BuildOptions) -> tuple[str, str]:
    """How the image of `name` gets its network: (given | standin | none, what it is); an error naming the
    file and where it is published when there is none."""
    w = weights_of(name)
    if w is None:
        return "none", ""
    if w.name in opts.weights:
        missing = [f for f in w.companions if f not in opts.weights]
        if missing:
            raise SlamRunError(
                f"{name} needs {', '.join(w.files)} together: give {' and '.join(missing)} too, each with "
                f"--weights NAME=FILE (or =URL#sha256=HEX). They are published in {w.published}"
            )
        return "given", ", ".join(w.files)
    if w.standin and opts.standin_model:
        return "standin", f"untrained stand-in with {w.name}'s interface: plumbing only, NOT the trained network"
    how = " (or --standin-model for an untrained stand-in that tests the plumbing only)" if w.standin else ""
    raise SlamRunError(
        f"{name} needs {', '.join(w.files)}, which cannot be downloaded here: give "
        f"{'each with --weights NAME=FILE' if w.companions else f'it with --weights {w.name}=FILE'} "
        f"(or =URL#sha256=HEX){how}. It is published in {w.published}"
    )


def sources_of(dockerfile: Path) -> list[str]:
    """The upstream sources a Dockerfile (with its shared stages) copies from the build context
    (`sources/<name>.tar.gz`)."""
    names = []
    for line in recipe_text(dockerfile).splitlines():
        if line.strip().upper().startswith(("COPY", "ADD")):
            names += [n for n in SOURCE_RE.findall(line) if n not in names]
    unknown = [n for n in names if n not in src.SOURCES]
    if unknown:
        raise SlamRunError(
            f"{dockerfile}: copies unknown source(s) {', '.join(unknown)} (known: {', '.join(src.SOURCES)})"
        )
    return names


def vocabulary_choice(name: str, archives: dict[str, Path], opts: BuildOptions) -> tuple[str, str]:
    """How the image of `name` gets its vocabulary: (source | given | trained | none, what it is)."""
    vocab = vocabulary_of(name)
    if vocab is None:
        return "none", ""
    given = opts.vocabulary.get(name) or opts.vocabulary.get("*")
    if vocab.path in src.archive_members(archives[vocab.source]):
        if given:
            return "given", f"{Path(given).name} sha256 {src.file_sha256(Path(given))} (overrides the source's)"
        return "source", f"{vocab.path} from {src.SOURCES[vocab.source].repo}@{src.SOURCES[vocab.source].commit}"
    if given:
        if not Path(given).is_file():
            raise SlamRunError(f"{given}: vocabulary file not found")
        return "given", f"{Path(given).name} sha256 {src.file_sha256(Path(given))}"
    if opts.train_vocabulary:
        return "trained", f"{vocab.format} trained at build time on synthetic frames (slamrun synth); not the study's"
    repo = src.SOURCES[vocab.source]
    raise SlamRunError(
        f"{name} needs its vocabulary {vocab.path} ({vocab.format}), which the source archive "
        f"{archives[vocab.source]} lacks: give the file with --vocabulary {name}=FILE (it is in the repository "
        f"{repo.repo} at {vocab.path}), or let the build train a small one (without --no-train-vocabulary)"
    )


def recipe_owner(dockerfile: Path) -> Path:
    """The folder a recipe belongs to: a method's folder for its image/Dockerfile, else the Dockerfile's own folder
    (a recipe written anywhere else builds with nothing around it but its folder)."""
    return dockerfile.parent.parent if dockerfile.parent.name == "image" else dockerfile.parent


def copy_code(dockerfile: Path, ctx: Path) -> None:
    """The code a build context holds: the method's own folder as `method/` (no other method's), the shared recipe
    parts as `recipes/`, the modules families share (a GPU process's helpers) as `methods/`."""
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
    shutil.copytree(recipe_owner(dockerfile), ctx / "method", ignore=ignore)
    shutil.copytree(METHODS / "recipes", ctx / "recipes", ignore=ignore)
    (ctx / "methods").mkdir()
    for module in METHODS.glob("*.py"):
        shutil.copyfile(module, ctx / "methods" / module.name)


def assemble_context(name: str, dockerfile: Path, opts: BuildOptions, ctx: Path, log: Callable[[str], None]) -> dict:
    """Fill `ctx` with what the build of `name` reads; returns the labels describing it."""
    model, model_detail = model_choice(name, opts)  # a missing network is said before anything is fetched
    copy_code(dockerfile, ctx)
    (ctx / "sources").mkdir()
    inputs = ctx / "inputs"
    inputs.mkdir()
    (inputs / "README").write_text("Inputs of an image build (vocabulary, weights, training frames).\n")
    archives = {}
    for s in sources_of(dockerfile):
        path = src.obtain(s, opts.sources_dir, opts.source_cache, opts.source_url)
        archives[s] = path
        _link_or_copy(path, ctx / "sources" / f"{s}.tar.gz")
        log(f"source {s}: {src.SOURCES[s].repo}@{src.SOURCES[s].commit} ({path})")
    labels = {
        f"{LABEL}.method": name,
        f"{LABEL}.march": opts.march,
        f"{LABEL}.sources": json.dumps({s: f"{src.SOURCES[s].repo}@{src.SOURCES[s].commit}" for s in archives}),
    }
    kind, detail = vocabulary_choice(name, archives, opts)
    if kind != "none":
        labels[f"{LABEL}.vocabulary"] = f"{kind}: {detail}"
        log(f"vocabulary of {name}: {kind}: {detail}")
        if kind == "given":
            given = opts.vocabulary.get(name) or opts.vocabulary.get("*")
            (inputs / "vocabulary").mkdir()
            shutil.copyfile(given, inputs / "vocabulary" / vocabulary_of(name).path.rsplit("/", 1)[-1])
        elif kind == "trained":
            training_frames(inputs / "train-frames")
    wheels = pypi_files_of(dockerfile)
    if wheels:
        (ctx / "pypi").mkdir()
        for filename in wheels:
            path = src.obtain_pypi(filename, opts.sources_dir, opts.source_cache)
            _link_or_copy(path, ctx / "pypi" / filename)
            log(f"PyPI file {filename} ({path})")
        labels[f"{LABEL}.pypi"] = json.dumps({f: src.PYPI_FILES[f].sha256 for f in wheels})
        labels |= toolchain_labels(dockerfile, wheels, opts.build_args)
    weights = {}
    if opts.weights:
        (inputs / "weights").mkdir()
        for wname, given in opts.weights.items():
            path = _weights_file(wname, str(given), opts)
            shutil.copyfile(path, inputs / "weights" / wname)
            weights[wname] = f"{path.name} sha256 {src.file_sha256(path)}"
    if model == "standin":
        weights[weights_of(name).name] = model_detail
    if weights:
        labels[f"{LABEL}.weights"] = json.dumps(weights)
        log(f"weights of {name}: {json.dumps(weights)}")
    w = weights_of(name)
    args = {"VOCABULARY": kind} | ({w.arg: model} if model != "none" and w.standin else {})
    labels[f"{LABEL}.build-args"] = json.dumps(args | opts.build_args)
    return labels


def _weights_file(name: str, given: str, opts: BuildOptions) -> Path:
    """A weights file given by path, or by address as URL#sha256=HEX (downloaded on this host, checked)."""
    if re.match(r"https?://", given):
        url, _, digest = given.partition("#sha256=")
        return src.obtain_url(url, digest.lower(), opts.source_cache)
    if not Path(given).is_file():
        raise SlamRunError(f"{given}: weights file {name} not found")
    return Path(given)


def training_frames(dest: Path, sequences: int = 3, frames: int = 120) -> None:
    """Frames a vocabulary is trained on: synthetic indoor and outdoor scenes (seeds far from the demo's)."""
    import zipfile

    from slamrun.datasets.make_synthetic import generate

    dest.mkdir(parents=True)
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(sequences):
            seq = generate(Path(tmp) / f"s{i}", frames=frames, seed=9000 + i, scene_kind=("indoor", "outdoor")[i % 2])
            with zipfile.ZipFile(seq / "images.zip") as zf:
                for member in zf.namelist()[::2]:
                    (dest / f"s{i}_{member}").write_bytes(zf.read(member))


def _link_or_copy(a: Path, b: Path) -> None:
    try:
        os.link(a, b)
    except OSError:
        shutil.copyfile(a, b)


def build(
    names: list[str] | None = None,
    log: Callable[[str], None] = print,
    opts: BuildOptions | None = None,
    only_missing: bool = False,
) -> list[BuildRecord]:
    """Build the images of `names` (default: all); returns a record per image built."""
    from slamrun.backends.docker import DockerBackend

    opts = opts or BuildOptions()
    targets = buildable()
    unknown = [n for n in names or [] if n not in targets]
    if unknown:
        raise SlamRunError(f"no image to build for {', '.join(unknown)} (methods with images: {', '.join(targets)})")
    client = DockerBackend().client.api
    records = []
    for name in names or list(targets):
        tag, dockerfile = targets[name]
        if not dockerfile.exists():
            raise SlamRunError(f"{dockerfile}: missing; every method with an image needs its image/ folder")
        if only_missing and client.images(name=tag):
            continue
        ensure_bases(client, dockerfile, log)
        records.append(build_one(client, name, tag, dockerfile, opts, log))
    return records


def debian_bases(dockerfile: Path) -> set[str]:
    """The `debian:<suite>-slim` images a recipe starts FROM (bookworm for most, bullseye for DynaSLAM)."""
    return set(re.findall(r"^FROM\s+(debian:[a-z]+-slim)\b", recipe_text(dockerfile), flags=re.MULTILINE))


def ensure_bases(client, dockerfile: Path, log: Callable[[str], None]) -> None:
    """Make a missing Debian base without a registry (scripts/make-offline-base.sh: debootstrap from the
    machine's Debian mirror, then docker import), as CI does for bookworm."""
    import subprocess

    for base in sorted(debian_bases(dockerfile)):
        if client.images(name=base):
            continue
        suite = base.split(":")[1].removesuffix("-slim")
        log(f"making the base image {base} from the Debian mirror (scripts/make-offline-base.sh, about a minute)")
        env = {**os.environ, "SUITE": suite, "TAG": base}
        done = subprocess.run(
            ["bash", str(ROOT / "scripts" / "make-offline-base.sh")], env=env, capture_output=True, text=True
        )
        if done.returncode != 0:
            raise InfraError(f"could not make the base image {base}: {(done.stderr or done.stdout).strip()[-500:]}")


def build_one(client, name: str, tag: str, dockerfile: Path, opts: BuildOptions, log) -> BuildRecord:
    """One `docker build` in an assembled context, logged to `<log_dir>/<name>.log` (a failed build's log too;
    a rebuild with every step cached leaves the log and record of the build that made the image)."""
    opts.log_dir.mkdir(parents=True, exist_ok=True)
    log_path = opts.log_dir / f"{name}.log"
    building = opts.log_dir / f"{name}.building.log"  # becomes log_path unless the image is unchanged
    log(f"building {tag} from {dockerfile} (log: {log_path})")
    t0 = time.monotonic()
    try:
        with tempfile.TemporaryDirectory(prefix=f"slamrun-build-{name}-") as tmp, open(building, "w") as logf:

            def note(line: str) -> None:
                logf.write(line + "\n")
                logf.flush()
                log(line)

            ctx = Path(tmp)
            labels = assemble_context(name, dockerfile, opts, ctx, note)
            recipe = recipe_text(dockerfile)
            (ctx / "Dockerfile.slamrun").write_text(recipe)
            args = {"MARCH": opts.march, "JOBS": str(opts.jobs), **json.loads(labels[f"{LABEL}.build-args"])}
            if METHOD_ARG.search(recipe):  # a recipe that places slamrun's process by the name
                args["METHOD"] = name
            note(f"build arguments: {json.dumps(args)}")
            run_build(client, ctx, tag, args, labels, logf, log, log_path, opts.no_cache)
    except BaseException:
        building.replace(log_path)
        raise
    seconds = time.monotonic() - t0
    info = client.inspect_image(tag)
    size_mb = info["Size"] / 2**20
    previous = last_record(name, opts.log_dir)
    if previous is not None and previous.tag == tag and previous.image_id == info["Id"]:
        # every step cached: the image is the one the previous build made, whose log and time the record keeps
        building.unlink()
        log(f"built {tag}: unchanged, every step cached (made in {previous.seconds / 60:.1f} min), {size_mb:.0f} MB")
        return previous
    building.replace(log_path)
    record = BuildRecord(
        name, tag, round(seconds, 1), round(size_mb, 1), str(log_path), labels, time.time(), info["Id"]
    )
    (opts.log_dir / f"{name}.json").write_text(json.dumps(asdict(record), indent=1))
    log(f"built {tag} in {seconds / 60:.1f} min, {size_mb:.0f} MB")
    return record


def run_build(client, ctx: Path, tag: str, args: dict, labels: dict, logf, log, log_path, no_cache=False) -> None:
    """Stream a build; an error names the step that failed, the end of its output and the log."""
    step, tail, error = "(before the first step)", [], None
    try:
        stream = client.build(
            path=str(ctx),
            dockerfile="Dockerfile.slamrun",
            tag=tag,
            rm=True,
            forcerm=True,
            nocache=no_cache,
            decode=True,
            buildargs=args,
            labels=labels,
        )
        for chunk in stream:
            text = ANSI.sub("", chunk.get("stream", ""))
            for line in text.splitlines():
                logf.write(line + "\n")
                if line.startswith("Step "):
                    step, tail = line, []
                    log(f"  {line}")
                elif line.strip():
                    tail = (tail + [line])[-20:]
            if "error" in chunk:
                error = chunk["error"].strip()
                logf.write(f"ERROR: {error}\n")
    except Exception as exc:  # noqa: BLE001 - the daemon refused the build or went away
        raise InfraError(f"building {tag}: the Docker daemon failed ({exc}); the build log is {log_path}") from None
    finally:
        logf.flush()
    if error:
        shown = "\n    ".join(tail[-12:])
        raise InfraError(
            f"building {tag} failed at {step}\n  {error}\n  last output:\n    {shown}\n  full build log: {log_path}"
        )


def image_labels(client, tag: str) -> dict[str, str]:
    """The slamrun.* labels of a built image ({} when it has none)."""
    labels = (client.inspect_image(tag).get("Config") or {}).get("Labels") or {}
    return {k: v for k, v in labels.items() if k.startswith(f"{LABEL}.")}


def last_record(name: str, log_dir: Path = DEFAULT_LOG_DIR) -> BuildRecord | None:
    path = log_dir / f"{name}.json"
    try:
        return BuildRecord(**json.loads(path.read_text()))
    except (OSError, ValueError, TypeError):
        return None


def describe() -> str:
    return json.dumps(
        {n: {"tag": t, "gpu": slamrun.methods.REGISTRY[n].gpu_capable} for n, (t, _) in buildable().items()}
    )
