"""The ground truth `slamrun evaluate` compares estimates with, and its defaults.

A sequence folder of any layout gives the campaign's ground truth: the layout's own reader (`open_sequence`), in
the camera's frame at the frames' times (EuRoC's body poses carried to the camera with T_BS and interpolated), with
the layout's default metrics. A ground-truth file is read as it is (TUM-Mono's groundtruthSync.txt, TUM, an
EuRoC/ASL state csv, KITTI poses with their times), with its dataset's metrics: TUM-Mono's for TUM-Mono's ground
truth (named groundtruthSync.txt, or shaped as it: poses at the start and the end, NaN rows between), ATE and RPE
for any other TUM file and an EuRoC csv, and KITTI's segments too for KITTI poses. Where that file is in another
frame than the camera's, a note says so and names the folder form.
"""

from __future__ import annotations

import io
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from slamrun.core.batch_eval import MAX_FILE_BYTES, file_problem
from slamrun.core.formats import FORMATS, read_trajectory, recognise
from slamrun.core.inputs import read_text_bounded
from slamrun.core.metrics import RpeInterval
from slamrun.core.trajectory import Trajectory, read_times
from slamrun.datasets.file_notes import EUROC_GT, TUMVI_GT, asl_file_note, asl_folder, layout_note
from slamrun.errors import DatasetError, TrajectoryFormatError

FORMAT_NAMES = {  # the trajectory formats (core/formats.py), and TUM-Mono's ground-truth file
    "tum-mono": "a TUM-Mono groundtruthSync.txt ('timestamp tx ty tz qx qy qz qw' rows, NaN rows kept)",
    **FORMATS,
    "kitti": "KITTI poses (12 numbers a row: the 3x4 pose, one row per frame of --times)",
}
# the metrics a ground-truth file is evaluated with when --metric is not given: its dataset's layout's defaults
# (TUM-Mono, TUM RGB-D, EuRoC, KITTI: tests/test_layout.py checks them), written here so that a file's evaluation
# loads no layout
FILE_DEFAULT_METRICS = {
    "tum-mono": ("tum-mono",),
    "tum": ("ate", "rpe"),
    "euroc": ("ate", "rpe"),
    "kitti": ("ate", "rpe", "kitti"),
}
FILE_LAYOUTS = {"tum-mono": "tum-mono", "tum": "tum-rgbd", "euroc": "euroc", "kitti": "kitti"}  # whose defaults
TUM_MONO_GT = "groundtruthSync.txt"  # TUM-Mono's ground truth by its name (else by its shape: tum_mono_shaped)


@dataclass(frozen=True, eq=False)
class GroundTruth:
    """A ground truth and how to evaluate against it: its metrics by default, the frame times of its sequence
    (a folder's: the rows of KITTI estimates), and what a user should know (said on stderr)."""

    trajectory: Trajectory
    source: Path
    layout: str | None  # the sequence's layout; None for a file read as it is
    default_metrics: tuple[str, ...]
    frame_times: np.ndarray | None = None
    notes: tuple[str, ...] = ()
    default_rpe: RpeInterval = RpeInterval()  # its dataset's RPE interval

    @property
    def is_folder(self) -> bool:
        return self.layout is not None


def open_groundtruth(
    path: Path, fmt: str | None = None, metrics: tuple[str, ...] | None = None, times: Path | None = None
) -> GroundTruth:
    """The ground truth at `path`: a sequence folder of any layout, or a file of format `fmt` (default: recognised
    from its first row, a TUM file as TUM-Mono's by its name or its shape). `metrics` are the ones asked for
    (checked against the file's format); `times`, the frame times of KITTI poses. DatasetError naming the file and
    what was expected."""
    path = Path(path)
    if path.is_dir():
        return sequence_groundtruth(path)
    if problem := file_problem(path, MAX_FILE_BYTES, "the ground truth (a file or a sequence folder)"):
        raise DatasetError(problem)
    given = fmt
    fmt = fmt or sniff_format(path, metrics)
    if metrics and "tum-mono" in metrics and fmt != "tum-mono":
        raise DatasetError(
            f"{path}: read as {FORMAT_NAMES[fmt]}, but --metric tum-mono needs {FORMAT_NAMES['tum-mono']}; "
            f"give the sequence folder (--gt {sequence_folder(path)}) to evaluate as a campaign does, or another "
            "--metric"
        )
    if fmt == "kitti" and times is None:
        raise DatasetError(f"{path}: KITTI poses carry no timestamps: give the sequence's times.txt with --times")
    frame_times = read_frame_times(times) if times is not None else None
    try:
        traj = _read_file(path, fmt, frame_times)
    except (DatasetError, TrajectoryFormatError) as exc:
        if (note := layout_note(path)) is None:
            raise
        raise DatasetError(f"{exc}. {note}") from None  # a layout's file in no format of evaluate's says so
    notes = file_notes(path, fmt)
    if given is None and not metrics and fmt == "tum" and traj.report.n_nonfinite_dropped:
        fmt, traj, notes = _tum_mono_by_shape(path, traj, notes)
    if not np.isfinite(traj.positions).all(axis=1).any():
        raise DatasetError(f"{path}: no finite pose; expected {FORMAT_NAMES[fmt]}")
    return GroundTruth(traj, path, None, FILE_DEFAULT_METRICS[fmt], frame_times, notes)


def sequence_groundtruth(root: Path) -> GroundTruth:
    """A sequence folder's ground truth as the campaign evaluates with it: its layout's reader, frame and times."""
    from slamrun.datasets.layouts import DEFAULT_METRICS, DEFAULT_RPE, GROUNDTRUTH_FILES, detect, names, open_sequence

    layout = detect(root)
    if layout is None:
        raise DatasetError(
            f"{root}: no sequence of a layout slamrun reads ({', '.join(names())}) in this folder (none of their "
            "files: mav0/cam0/, image_0/, rgb.txt, associations.txt, image_left/, times.txt, ...); expected a "
            "sequence folder or a ground-truth file"
        )
    seq = open_sequence(root, layout)
    gt = seq.groundtruth()
    if gt is None:
        raise DatasetError(f"{root}: a {layout} sequence without its ground truth ({GROUNDTRUTH_FILES[layout]})")
    return GroundTruth(gt, root, layout, DEFAULT_METRICS[layout], seq.timestamps, seq.notes, DEFAULT_RPE[layout])


def sniff_format(path: Path, metrics: tuple[str, ...] | None) -> str:
    """A ground-truth file's format from its first row: commas (an ASL csv), 12 numbers (KITTI poses), else TUM
    (TUM-Mono's groundtruthSync.txt when TUM-Mono's metric is asked for, or with no metric asked for when the file
    is named groundtruthSync.txt; a TUM file of TUM-Mono's shape under another name is told after it is read:
    `_tum_mono_by_shape`)."""
    fmt = recognise(path)
    if fmt != "tum":
        return fmt
    if metrics:
        return "tum-mono" if "tum-mono" in metrics else "tum"
    return "tum-mono" if path.name == TUM_MONO_GT else "tum"


def tum_mono_shaped(traj: Trajectory) -> bool:
    """Whether rows read with their NaN rows kept have the shape of TUM-Mono's ground truth (one row per frame,
    poses at the start and the end only): every row a pose or a NaN row (seven NaN), rows with a pose in the first
    half and in the last half (the benchmark's start and end segments), NaN rows between them over the middle row.
    A tracker's lost poses (NaN rows at the start or the end) or a motion capture's dropouts here and there are
    not."""
    pose = np.column_stack([traj.positions, traj.quaternions])
    posed, blank = np.isfinite(pose).all(axis=1), np.isnan(pose).all(axis=1)
    n = len(pose)
    if n < 3 or not (posed | blank).all():
        return False
    half = n // 2
    return bool(posed[:half].any() and posed[n - half :].any() and blank[(n - 1) // 2 : half + 1].all())


def _tum_mono_by_shape(path: Path, traj: Trajectory, notes: tuple[str, ...]) -> tuple[str, Trajectory, tuple[str, ...]]:
    """A TUM file with NaN rows, no format nor metric asked for: TUM-Mono's ground truth under another name where
    its rows have that shape (`tum_mono_shaped`), read again with its NaN rows kept and said on stderr; else the
    TUM trajectory as read (its NaN rows dropped). A plain TUM file (no NaN row) is never read twice."""
    try:
        sync = read_groundtruth_sync(path)
    except DatasetError:
        return "tum", traj, notes
    if not tum_mono_shaped(sync):
        return "tum", traj, notes
    note = (
        f"{path}: TUM-Mono's ground truth (poses at the start and the end, NaN rows between): evaluated with "
        "TUM-Mono's metric; --metric ate --metric rpe for ATE and RPE over its poses"
    )
    return "tum-mono", sync, (*notes, note)


def file_notes(path: Path, fmt: str) -> tuple[str, ...]:
    """What a ground-truth file given as it is means for the figures, where it is in another frame (or at other
    times) than a campaign evaluates in: its layout's note, or the note of any ASL state csv."""
    if (note := layout_note(path)) is not None:
        return (note,)
    if fmt == "euroc":
        return (asl_file_note(path, "the body (IMU) frame", "the camera's extrinsics"),)
    return ()


def sequence_folder(path: Path) -> str:
    """The sequence folder an ASL csv lies in (SEQ/mav0/NAME/data.csv), or a placeholder."""
    found = (asl_folder(path, rel) for rel in (EUROC_GT, TUMVI_GT))
    return next((folder for folder in found if folder is not None), "SEQUENCE_FOLDER")


def read_frame_times(path: Path) -> np.ndarray:
    """Frame times (KITTI's times.txt or TUM-Mono's times.txt) from outside: a regular file within bounds, finite
    and increasing times."""
    if problem := file_problem(path, MAX_FILE_BYTES, "frame times (the sequence's times.txt)"):
        raise DatasetError(problem)
    times = read_times(path)
    if not len(times):
        raise DatasetError(f"{path}: no frame time; expected one time in seconds per line")
    bad = np.flatnonzero(~np.isfinite(times))
    if len(bad):
        raise DatasetError(f"{path}: frame time {bad[0] + 1} is {times[bad[0]]}; expected finite times in seconds")
    back = np.flatnonzero(np.diff(times) <= 0)
    if len(back):
        raise DatasetError(f"{path}: frame time {back[0] + 2} is not after the one before; expected increasing times")
    return times


def _read_file(path: Path, fmt: str, times: np.ndarray | None) -> Trajectory:
    if fmt == "tum-mono":  # a ground-truth form only: NaN rows kept
        return read_groundtruth_sync(path)
    return read_trajectory(path, fmt, times)


def read_groundtruth_sync(path: Path) -> Trajectory:
    """A groundtruthSync.txt from outside, NaN rows kept (they split the benchmark's segments): bounded, each
    problem named with its line."""
    text = read_text_bounded(path, MAX_FILE_BYTES, "the ground truth", DatasetError)
    expected = FORMAT_NAMES["tum-mono"]
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # "input contained no data"
            data = np.loadtxt(io.StringIO(text), comments="#", ndmin=2, dtype=float)
    except ValueError:
        data = None
    if data is None or data.shape[1:] != (8,):
        raise DatasetError(_first_bad_line(path, text, 8) + f"; expected {expected}")
    if not len(data):
        raise DatasetError(f"{path}: no pose row; expected {expected}")
    if np.any(~np.isfinite(data[:, 0])) or np.any(np.diff(data[:, 0]) <= 0):
        raise DatasetError(f"{path}: timestamps are not finite and strictly increasing; expected {expected}")
    return Trajectory(data[:, 0], data[:, 1:4], data[:, 4:8])


def _first_bad_line(path: Path, text: str, ncols: int) -> str:
    for n, line in enumerate(text.splitlines(), start=1):
        cells = line.split("#", 1)[0].split()
        if not cells:
            continue
        if len(cells) != ncols:
            return f"{path}:{n}: {len(cells)} values, not {ncols}: {line.strip()[:80]!r}"
        try:
            [float(c) for c in cells]
        except ValueError:
            return f"{path}:{n}: not a number in {line.strip()[:80]!r}"
    return f"{path}: no pose row"
