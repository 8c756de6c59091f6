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
RECOGNISED = "auto"  # the format name that asks for the file's first row to tell (`recognise`)


def recognise(path: str | Path) -> str:
    """A trajectory file's format from its first row (comments and blank lines skipped): commas are an ASL csv
    (euroc), 12 numbers KITTI poses, anything else TUM."""
    first = first_row(path)
    if "," in first:
        return "euroc"
    return "kitti" if len(first.split()) == 12 else "tum"


def first_row(path: str | Path) -> str:
    """The first row of a file that is neither blank nor a comment ('' when there is none)."""
    with open(path, "rb") as f:  # a regular file (checked by the caller): its first 64 KiB hold the first row
        head = f.read(65536).decode("utf-8", errors="replace")
    return next((ln for ln in head.splitlines() if ln.strip() and not ln.lstrip().startswith("#")), "")


def read_trajectory(path: str | Path, fmt: str = RECOGNISED, times: np.ndarray | None = None) -> Trajectory:
    """The poses of a file of format `fmt` (`auto`: told by its first row; KITTI's at the frame `times`): the one
    place a reader is chosen. TrajectoryFormatError naming the file."""
    from slamrun.core import trajectory as t

    if fmt == RECOGNISED:
        fmt = recognise(path)
    if fmt == "tum":
        return t.read_tum(path)
    if fmt == "euroc":
        return t.read_euroc_csv(path)
    if fmt == "kitti":
        if times is None:
            raise ValueError("KITTI poses carry no timestamps: give the sequence's frame times (--times FILE)")
        return t.read_kitti(path, times)
    raise ValueError(f"unknown trajectory format {fmt!r}; known: {', '.join(FORMATS)}")
