"""The prepared view: what a method sees of a sequence, and the contract every adapter and backend uses.

A view folder holds the frames in presentation order (`images/000000.<ext>`), the timestamp files
methods need (times.txt `id t exposure`, rgb.txt, images.txt, times_single.txt), and calibration
(camera.txt for the view's images; for `native` also pcalib.txt and vignette.png; for `rectified` the
pinhole K in camera_pinhole.json). Backward views present reversed frames with mirror time
t' = t_first + t_last - t, so every view has increasing timestamps; `to_original` maps poses back.
Building views is the cache's job (slamrun.datasets.cache).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path

import numpy as np

from slamrun.core.nearest import nearest
from slamrun.core.trajectory import Trajectory


class Direction(StrEnum):
    forward = "forward"
    backward = "backward"

    @property
    def opposite(self) -> Direction:
        """The other direction (its views play the same frames in reverse order)."""
        return Direction.backward if self is Direction.forward else Direction.forward


class Profile(StrEnum):
    native = "native"  # original frames + FOV camera.txt, pcalib, vignette (DSO family, LSD-SLAM, SVO)
    rectified = "rectified"  # pinhole frames by the camera.txt output rule, zero distortion


@dataclass(frozen=True)
class PreparedView:
    """A prepared view on disk. Paths are relative to `root`, so a container can see it at /data."""

    root: Path
    sequence: str
    direction: Direction
    profile: Profile
    n_frames: int
    t_first: float
    t_last: float
    width: int
    height: int
    pinhole: tuple[float, float, float, float] | None  # fx fy cx cy in pixels, for rectified views
    frame_suffix: str = ".png"  # frames are images/<6-digit index><suffix>
    photometric: bool = True  # pcalib.txt and vignette.png are in the view (native views of TUM-Mono)
    build_id: str = ""  # which build of the view (slamrun.datasets.cache): a rebuilt view is another folder and id
    perturbation: str = "none"  # how its frames were made worse (slamrun.datasets.perturb), `none` for the baseline

    images_dir = "images"
    times = "times.txt"
    rgb = "rgb.txt"
    images_list = "images.txt"
    times_single = "times_single.txt"
    camera = "camera.txt"
    pcalib = "pcalib.txt"
    vignette = "vignette.png"

    def path(self, name: str) -> Path:
        return self.root / name

    def at(self, root: Path | str) -> PreparedView:
        """The same view seen at another mount point (e.g. /data inside a container)."""
        return PreparedView(**{**self.__dict__, "root": Path(root)})

    def to_original(self, traj: Trajectory) -> Trajectory:
        """A trajectory in view time → the same poses at their original frame timestamps.

        Times within 0.1 ms of a frame snap to that frame's original timestamp exactly (files carry
        rounded decimals); other times are mapped arithmetically.
        """
        t = traj.timestamps if self.direction is Direction.forward else self.t_first + self.t_last - traj.timestamps
        originals = self.original_timestamps()
        if len(originals) and len(t):
            row, distance = nearest(originals, t)
            t = np.where(distance < 1e-4, originals[row], t)
        return traj.with_timestamps(t)

    def original_timestamps(self) -> np.ndarray:
        """The sequence's original frame timestamps, increasing (full precision)."""
        return np.loadtxt(self.root / "original_times.txt", ndmin=1)

    def view_timestamps(self) -> np.ndarray:
        data = np.loadtxt(self.root / self.times, ndmin=2)
        return data[:, 1]

    @classmethod
    def load(cls, root: Path) -> PreparedView:
        meta = json.loads((root / "view.json").read_text())
        return cls(
            root=root,
            sequence=meta["sequence"],
            direction=Direction(meta["direction"]),
            profile=Profile(meta["profile"]),
            n_frames=meta["n_frames"],
            t_first=meta["t_first"],
            t_last=meta["t_last"],
            width=meta["width"],
            height=meta["height"],
            pinhole=tuple(meta["pinhole"]) if meta["pinhole"] else None,
            frame_suffix=meta.get("frame_suffix", ".png"),
            photometric=meta.get("photometric", meta["profile"] == Profile.native.value),
            build_id=meta.get("build_id", ""),
            perturbation=meta.get("perturbation", "none"),
        )
