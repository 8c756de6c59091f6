"""Built images as archives, for machines without a Docker daemon (podman, a cluster's nodes)."""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

from slamrun.errors import InfraError


def archive_name(tag: str) -> str:
    """slamrun/dso:latest -> slamrun_dso.tar (":latest" left out)."""
    return tag.removesuffix(":latest").replace("/", "_").replace(":", "_") + ".tar"


def export_image(client, tag: str, dest: Path) -> tuple[Path, str]:
    """Write `tag` as a docker-archive (`podman load -i` and `docker load -i` read it); returns (path, sha256).
    Written beside and renamed, so an interrupted export leaves no archive that looks complete."""
    import docker

    try:
        image = client.images.get(tag)
    except docker.errors.ImageNotFound:
        raise InfraError(f"image {tag} is not built here; build it first: make images METHOD=...") from None
    dest.mkdir(parents=True, exist_ok=True)
    path = dest / archive_name(tag)
    tmp = path.with_name(path.name + ".part")
    digest = hashlib.sha256()
    with open(tmp, "wb") as fh:
        for chunk in image.save(named=True):
            digest.update(chunk)
            fh.write(chunk)
        fh.flush()
        os.fsync(fh.fileno())
    tmp.replace(path)
    return path, digest.hexdigest()
