"""Build the methods' Docker images by tag, from the registry's list: `make images [METHOD=name]`."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import methods
from runner.errors import InfraError, SlamRunError

ROOT = Path(__file__).resolve().parents[1]


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
    client = DockerBackend().client.api
    built = []
    for name in names or list(targets):
        tag, dockerfile = targets[name]
        if not dockerfile.exists():
            raise SlamRunError(f"{dockerfile}: missing; every method with an image needs its docker/<name>/ folder")
        log(f"building {tag} from {dockerfile.relative_to(ROOT)}")
        error = None
        for chunk in client.build(
            path=str(ROOT),
            dockerfile=str(dockerfile.relative_to(ROOT)),
            tag=tag,
            rm=True,
            decode=True,
            buildargs=build_args or {},
        ):
            if "stream" in chunk:
                text = chunk["stream"].rstrip()
                if text:
                    log(f"  {text}")
            if "error" in chunk:
                error = chunk["error"]
        if error:
            raise InfraError(f"building {tag} failed: {error.strip()}")
        built.append(tag)
    return built


def describe() -> str:
    return json.dumps({n: {"tag": t, "gpu": methods.REGISTRY[n].gpu_capable} for n, (t, _) in buildable().items()})
