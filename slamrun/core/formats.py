"""The trajectory file formats slamrun reads and writes, in one map (as evo's file_interface): `slamrun evaluate`,
`slamrun import`, batch evaluation and the ground truth read through it. Light on purpose (the readers are imported
when a file is read), so the command line offers the names without loading NumPy."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import numpy as np

    from slamrun.core.trajectory import Trajectory

FORMATS = {  # name -> what a file of it holds
    "tum": "a TUM trajectory ('timestamp tx ty tz qx qy qz qw' rows)",
    "euroc": "an EuRoC/ASL state csv (#timestamp [ns], p_RS_R xyz, q_RS wxyz, ...)",
    "kitti": "KITTI poses (12 numbers a row: the 3x4 pose, one row per frame of the sequence's times)",
}
NEEDS_TIMES = ("kitti",)  # formats whose rows carry no time: the frames' times are given beside them


def read_trajectory(path: str | Path, fmt: str, times: np.ndarray | None = None) -> Trajectory:
    """The poses of a file of format `fmt` (KITTI's at the frame `times`); TrajectoryFormatError naming the file."""
    from slamrun.core import trajectory as t

    if fmt == "tum":
        return t.read_tum(path)
    if fmt == "euroc":
        return t.read_euroc_csv(path)
    if fmt == "kitti":
        if times is None:
            raise ValueError("KITTI poses are read at the frames' times: give them")
        return t.read_kitti(path, times)
    raise ValueError(f"unknown trajectory format {fmt!r}; known: {', '.join(FORMATS)}")
