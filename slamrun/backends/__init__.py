"""Backends run one run's process: a local process tree, a Docker container, or either on a Dask worker.

Choosing one belongs here, beside them; the campaign and the Dask workers both ask `make_backend`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from slamrun.backends.this_machine import make_local_backend

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
