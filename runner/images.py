"""Build the methods' Docker images by tag, from the registry's list: `make images [METHOD=name]`."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import methods
from runner.errors import InfraError, SlamRunError

ROOT = Path(__file__).resolve().parents[1]
# Base images the method images build FROM, with their folders: built first, when missing.
BASES = {"slamrun/tensorflow-cc:1.6": ROOT / "docker" / "tensorflow_cc" / "Dockerfile"}


def buildable() -> dict[str, tuple[str, Path]]:
    """Registered methods with an image: name → (tag, Dockerfile)."""
    out = {}
    for name, cls in sorted(methods.REGISTRY.items()):
        if cls.image:
            out[name] = (cls.image, ROOT / "docker" / name / "Dockerfile")
    return out


def build(
    names: list[str] | None = None, log: Callable[[str], None] = print, build_args: dict | None = None
) -> list[str]:
    """Build the images of `names` (default: all); returns the tags built. The build context is the repo."""
    from runner.backends.docker import DockerBackend

    targets = buildable()
    unknown = [n for n in names or [] if n not in targets]
    if unknown:
        raise SlamRunError(f"no image to build for {', '.join(unknown)} (methods with images: {', '.join(targets)})")
    backend = DockerBackend()
    client = backend.client.api
    built = []
    for name in names or list(targets):
        tag, dockerfile = targets[name]
        if not dockerfile.exists():
            raise SlamRunError(f"{dockerfile}: missing; every method with an image needs its docker/<name>/ folder")
        for base in bases_of(dockerfile):
            if not client.images(name=base):
                built += _build_one(client, base, BASES[base], log, build_args)
        built += _build_one(client, tag, dockerfile, log, build_args)
    return built


def bases_of(dockerfile: Path) -> list[str]:
    """The project's own base images a Dockerfile builds FROM."""
    froms = [line.split()[1] for line in dockerfile.read_text().splitlines() if line.upper().startswith("FROM ")]
    return [f for f in froms if f in BASES]


def _build_one(client, tag: str, dockerfile: Path, log, build_args) -> list[str]:
    log(f"building {tag} from {dockerfile.relative_to(ROOT)}")
    error = None
    stream = client.build(
        path=str(ROOT),
        dockerfile=str(dockerfile.relative_to(ROOT)),
        tag=tag,
        rm=True,
        decode=True,
        buildargs=build_args or {},
    )
    for chunk in stream:
        text = chunk.get("stream", "").rstrip()
        if text:
            log(f"  {text}")
        error = chunk.get("error", error)
    if error:
        raise InfraError(f"building {tag} failed: {error.strip()}")
    return [tag]


def describe() -> str:
    return json.dumps({n: {"tag": t, "gpu": methods.REGISTRY[n].gpu_capable} for n, (t, _) in buildable().items()})
