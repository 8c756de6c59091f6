"""What `slamrun evaluate` says of a built-in layout's ground-truth file given as it is (an ASL state csv of EuRoC or
TUM-VI, ICL-NUIM's *.gt.freiburg, TartanAir's pose_left.txt): the frame or times it holds that a campaign does not
evaluate in, and the sequence folder that evaluates as the campaign does. Light on purpose (pathlib only), so that a
file's evaluation loads no layout; each of those layouts names its note here (`LAYOUT.file_note`) and takes from here
the facts the note states (where its ground truth lies, its frame rate)."""

from __future__ import annotations

from pathlib import Path

EUROC_GT = Path("mav0/state_groundtruth_estimate0/data.csv")  # EuRoC's state ground truth (body frame)
TUMVI_GT = Path("mav0/mocap0/data.csv")  # TUM-VI's motion capture (IMU frame)
ICL_NUIM_FPS = 30.0  # ICL-NUIM's frame k is at k / 30 s
TARTANAIR_POSES, TARTANAIR_FPS = "pose_left.txt", 20.0  # TartanAir's poses, one a frame; frame k at k / 20 s


def asl_file_note(path: Path, frame: str, how: str, folder: str = "SEQUENCE_FOLDER") -> str:
    """What an ASL state csv given to `slamrun evaluate` as it is means for the figures, and the folder form that
    evaluates as the campaign does (`folder`: the sequence's, where the csv lies in one)."""
    return (
        f"{path}: an ASL state csv holds the poses of {frame} at its own times; a campaign evaluates the camera's "
        f"poses at the frames (carried by {how}, interpolated), so figures against this file differ from "
        f"results.csv's. To evaluate as the campaign does, give the sequence folder: --gt {folder}"
    )


def asl_folder(path: Path, gt_rel: Path) -> str | None:
    """The sequence folder an ASL csv lies in as `gt_rel` (SEQ/mav0/NAME/data.csv), or None."""
    parts = path.parts
    if len(parts) >= 3 and parts[-3:-1] == gt_rel.parts[-3:-1]:
        return str(Path(*parts[:-3]))
    return None


def euroc(path: Path) -> str | None:
    """EuRoC's state ground truth given as it is: in the body (IMU) frame."""
    folder = asl_folder(path, EUROC_GT)
    return None if folder is None else asl_file_note(path, "the body (IMU) frame", "the camera's T_BS", folder)


def tum_vi(path: Path) -> str | None:
    """TUM-VI's motion-capture ground truth given as it is: in the IMU frame."""
    folder = asl_folder(path, TUMVI_GT)
    return None if folder is None else asl_file_note(path, "the IMU frame", "the camera's T_cam_imu", folder)


def icl_nuim(path: Path) -> str | None:
    """An ICL-NUIM *.gt.freiburg given as it is: frame numbers for times, and the y-up camera."""
    if not path.name.endswith(".gt.freiburg"):
        return None
    return (
        f"{path}: ICL-NUIM's poses as the release has them: frame numbers for times and a y-up camera (fy -480); a "
        f"campaign evaluates frame k at k/{ICL_NUIM_FPS:g} s against these poses mirrored into the y-down camera "
        f"methods see (fy +480). To evaluate as the campaign does, give the sequence folder: --gt {path.parent}"
    )


def tartanair(path: Path) -> str | None:
    """TartanAir's pose_left.txt given as it is: no times, NED axes."""
    if path.name != TARTANAIR_POSES:
        return None
    return (
        f"{path}: TartanAir's poses have no times and are in NED axes; give the sequence folder (--gt "
        f"{path.parent}): it times frame k at k/{TARTANAIR_FPS:g} s and carries the poses to the camera's axes"
    )


NOTES = (euroc, tum_vi, icl_nuim, tartanair)  # the built-in layouts' (tests/test_layout.py checks it against them)


def layout_note(path: Path) -> str | None:
    """A built-in layout's note on one of its ground-truth files, or None. Plug-ins are not consulted for a file
    (evaluating files never pays for scanning the installed packages)."""
    return next((note for note_of in NOTES if (note := note_of(path))), None)
