"""Datasets: layouts, sequences and the prepared views methods read. The plug-in API for a dataset layout.

A plug-in imports what it needs from here (`from slamrun.datasets import Layout, Sequence, ...`); the names are
loaded on first use, so `import slamrun.datasets` costs nothing and no layout module is imported before one is
asked for. Everything else under slamrun/ may move between releases.
"""

from __future__ import annotations

import importlib

_PUBLIC = {
    # a layout and what its reader returns
    "Layout": "slamrun.datasets.protocol",
    "Download": "slamrun.datasets.protocol",
    "Sequence": "slamrun.datasets.sequence",
    "IMAGE_SUFFIXES": "slamrun.datasets.sequence",
    "folder_sequence": "slamrun.datasets.sequence",
    "check_regular": "slamrun.datasets.sequence",
    "read_text": "slamrun.datasets.sequence",
    "time_problem": "slamrun.datasets.sequence",
    "camera_problem": "slamrun.datasets.sequence",
    "interpolate_poses": "slamrun.datasets.sequence",
    "nearest_poses": "slamrun.datasets.sequence",
    # what a layout's synthetic writer is handed
    "Synth": "slamrun.datasets.synth",
    # the view a method reads
    "PreparedView": "slamrun.datasets.view",
    "Profile": "slamrun.datasets.view",
    "Direction": "slamrun.datasets.view",
    # cameras and trajectories a reader builds
    "CameraFile": "slamrun.core.camera",
    "PinholeCamera": "slamrun.core.camera",
    "FovCamera": "slamrun.core.camera",
    "Trajectory": "slamrun.core.trajectory",
    "rotmat_to_quat": "slamrun.core.trajectory",
    # the error a reader raises for a bad file
    "DatasetError": "slamrun.errors",
}
__all__ = sorted(_PUBLIC)


def __getattr__(name: str):
    if name in _PUBLIC:
        value = getattr(importlib.import_module(_PUBLIC[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'slamrun.datasets' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_PUBLIC))
