"""The backend that runs a run's process on this machine (a Dask worker asks for it too, so it is apart from the
choice in __init__, which may pick Dask)."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from slamrun.backends.base import Backend


def make_local_backend(name: str) -> Backend:
    """A local process tree, or a Docker or podman container."""
    if name == "local":
        from slamrun.backends.local import LocalBackend

        return LocalBackend()
    if name == "podman":
        from slamrun.backends.podman import PodmanBackend

        return PodmanBackend()
    from slamrun.backends.docker import DockerBackend

    return DockerBackend()
