"""Backends run one run's process: a local process tree, a Docker container, or either on a Dask worker.

Choosing one belongs here, beside them; the campaign and the Dask workers both ask `make_backend`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from slamrun.backends.base import Backend
    from slamrun.engine.spec import CampaignSpec


def make_backend(spec: CampaignSpec) -> Backend:
    """The backend a spec asks for: on a Dask cluster when it has `distributed:`, else on this machine."""
    if spec.distributed is not None:
        from slamrun.backends.dask import DaskBackend

        d = spec.distributed
        if d.cluster is not None:
            return DaskBackend(spec.backend, None, spec.results, local_workers=spec.lanes, jobs=d)
        return DaskBackend(spec.backend, d.address, spec.results, local_workers=spec.lanes)
    return make_local_backend(spec.backend)


def make_local_backend(name: str) -> Backend:
    """The backend that runs a process on this machine: a local process tree, or a Docker or podman container."""
    if name == "local":
        from slamrun.backends.local import LocalBackend

        return LocalBackend()
    if name == "podman":
        from slamrun.backends.podman import PodmanBackend

        return PodmanBackend()
    from slamrun.backends.docker import DockerBackend

    return DockerBackend()
