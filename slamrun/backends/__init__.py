"""Backends run one run's process: a local process tree, a Docker container, or either on a Dask worker.

Choosing one belongs here, beside them; the campaign and the Dask workers both ask `make_backend`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from slamrun.backends.this_machine import make_local_backend

if TYPE_CHECKING:
    from pathlib import Path

    from slamrun.backends.base import Backend
    from slamrun.backends.distributed import DistributedSpec


def make_backend(backend: str, results: Path, lanes: int, distributed: DistributedSpec | None = None) -> Backend:
    """The backend a spec asks for (its `backend:`, `results:`, `lanes:` and `distributed:`, not the whole spec): on a
    Dask cluster when it has `distributed:`, else on this machine."""
    if distributed is not None:
        from slamrun.backends.dask import DaskBackend

        if distributed.cluster is not None:
            return DaskBackend(backend, None, results, local_workers=lanes, jobs=distributed)
        return DaskBackend(backend, distributed.address, results, local_workers=lanes)
    return make_local_backend(backend)
