"""EuRoC MAV, and the ASL layout it shares with TUM-VI (slamrun.datasets.tum_vi): `mav0/cam0/` (data.csv with
nanosecond timestamps, data/), the first camera only.

EuRoC: `mav0/cam0/sensor.yaml` (pinhole intrinsics, radial-tangential distortion, T_BS: camera to body) and the
ground truth `mav0/state_groundtruth_estimate0/data.csv` (the body, i.e. IMU, poses at 200 Hz).
Camera poses are body poses times the camera's extrinsics, interpolated at the frames' times. Written
synthetically with the real rig's distortion and T_BS; downloaded as the site's per-sequence zip.
"""

from __future__ import annotations

import os
import reprlib
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from slamrun.core.camera import CameraFile, FovCamera, PinholeCamera, RadTanCamera
from slamrun.core.inputs import load_yaml_file
from slamrun.core.trajectory import Trajectory, read_euroc_csv
from slamrun.datasets import file_notes, frames
from slamrun.datasets.file_notes import EUROC_GT
from slamrun.datasets.protocol import Download, Layout, Placed
from slamrun.datasets.sequence import (
    IMAGE_SUFFIXES,
    MAX_POSITION_M,
    Sequence,
    camera_problem,
    check_positions,
    check_regular,
    folder_sequence,
    frame_list_problem,
    interpolate_poses,
    raise_problems,
    read_groundtruth,
    read_text,
    require_regular,
    sequence_folder,
    transform_poses,
)
from slamrun.errors import DatasetError

if TYPE_CHECKING:
    from slamrun.datasets.synth import Synth

CAM = Path("mav0/cam0")
FRAME_LIST = CAM / "data.csv"  # the ASL layout's frames (#timestamp [ns],filename), EuRoC's and TUM-VI's
GT_MAX_GAP_S = 0.02  # ground truth is interpolated between samples at most this far from a frame
MAX_NS = 2**63 - 1  # EuRoC's stamps are int64 nanoseconds


def open_euroc(root: str | Path) -> Sequence:
    return open_asl(Path(root), "euroc", CAM / "sensor.yaml", EUROC_GT, read_sensor_yaml)


def open_asl(
    root: Path,
    layout: str,
    calib_rel: Path,
    gt_rel: Path,
    read_calib: Callable[[Path], tuple[CameraFile, np.ndarray]],
    notes: tuple[str, ...] = (),
) -> Sequence:
    """A sequence of the ASL layout: its frames (mav0/cam0), the camera and its extrinsics T_body_cam read from
    `calib_rel` by `read_calib`, the body's ground truth `gt_rel` carried to the camera."""
    root = sequence_folder(root)
    csv, calib, gt_path = root / FRAME_LIST, root / calib_rel, root / gt_rel
    require_regular(root, layout, [csv, calib, gt_path])
    problems: list[str] = []
    for p, what in ((csv, "the frame list (#timestamp [ns],filename)"), (calib, "the camera calibration")):
        if not p.is_file():
            problems.append(f"{p}: missing; expected {what}")
    camera, t_body_cam = None, None
    if calib.is_file():
        try:
            camera, t_body_cam = read_calib(calib)
        except DatasetError as exc:
            problems.append(str(exc))
        if camera is not None and (problem := camera_problem(calib, camera)):
            problems.append(problem)
            camera = None
    names, ns = ([], None)
    if csv.is_file():
        names, ns = _read_frame_list(csv, problems)
    images = root / CAM / "data"
    if names:
        missing = [n for n in names if not ((images / n).exists() or (images / n).is_symlink())]
        if missing:
            problems.append(f"{images}: {len(missing)} frame(s) listed in {csv.name} missing (e.g. {missing[0]})")
        else:
            size = (camera.camera.width, camera.camera.height) if camera is not None else None
            frames.check_files(images, names, size, problems, calib.name)
    raise_problems(root, layout, problems)
    assert camera is not None and ns is not None and t_body_cam is not None
    times = (ns // 1_000_000_000).astype(float) + (ns % 1_000_000_000).astype(float) * 1e-9

    def groundtruth() -> Trajectory:
        if problem := check_regular([gt_path], {gt_path}):
            raise DatasetError(problem[0])
        body = read_groundtruth(gt_path, read_euroc_csv)
        check_positions(body, gt_path)
        return transform_poses(interpolate_poses(body, times, GT_MAX_GAP_S), t_body_cam)

    return folder_sequence(root, layout, names, times, camera, images, (csv, calib), gt_path, groundtruth, notes)


def _read_frame_list(csv: Path, problems: list[str]) -> tuple[list[str], np.ndarray | None]:
    names, stamps = [], []
    for n, line in enumerate(read_text(csv).splitlines(), start=1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        cells = [c.strip() for c in line.split(",")]
        if len(cells) != 2:
            problems.append(f"{csv}:{n}: {len(cells)} columns; expected '#timestamp [ns],filename'")
            return [], None
        if not (cells[0].isascii() and cells[0].isdigit()):
            problems.append(
                f"{csv}:{n}: timestamp {cells[0][:40]!r} is not a whole number of nanoseconds (ASCII digits 0-9)"
            )
            return [], None
        if len(cells[0].lstrip("0")) > 19 or int(cells[0]) > MAX_NS:  # 19 digits: int() is quick and bounded
            problems.append(f"{csv}:{n}: timestamp {cells[0][:40]} ns is beyond 2^63 - 1 (EuRoC's are int64)")
            return [], None
        name = cells[1]
        if not name.lower().endswith(IMAGE_SUFFIXES) or "/" in name or name in (".", "..") or not name.isprintable():
            problems.append(f"{csv}:{n}: {name[:80]!r} is not an image file name in data/")
            return [], None
        stamps.append(int(cells[0]))
        names.append(cells[1])
    ns = np.array(stamps, dtype=np.int64)
    if problem := frame_list_problem(csv, ns, "timestamps"):
        problems.append(problem)
        return [], None
    return names, ns


def calibration_yaml(path: Path) -> dict:
    """A calibration YAML, read with slamrun.core.inputs' bounds (size, aliases, nesting)."""
    data = load_yaml_file(path, "the camera calibration", DatasetError)
    if not isinstance(data, dict):
        raise DatasetError(f"{path}: expected a mapping of calibration keys")
    return data


def yaml_numbers(path: Path, data: dict, key: str, count: int | tuple[int, ...]) -> list[float]:
    value = data.get(key)
    if isinstance(value, dict):  # T_BS: {cols, rows, data}
        value = value.get("data")
    counts = (count,) if isinstance(count, int) else count
    if (
        not isinstance(value, list)
        or len(value) not in counts
        or not all(isinstance(v, int | float) and np.isfinite(v) for v in value)
    ):
        want = " or ".join(str(c) for c in counts)
        raise DatasetError(f"{path}: {key}: expected a list of {want} finite numbers, found {short(value)}")
    return [float(v) for v in value]


def read_sensor_yaml(path: Path) -> tuple[CameraFile, np.ndarray]:
    """EuRoC's cam0/sensor.yaml → the camera (pinhole + radial-tangential; rectified with `crop`) and T_BS."""
    data = calibration_yaml(path)
    w, h = (int(v) for v in yaml_numbers(path, data, "resolution", 2))
    fx, fy, cx, cy = yaml_numbers(path, data, "intrinsics", 4)
    model = data.get("camera_model", "pinhole")
    if model != "pinhole":
        raise DatasetError(f"{path}: camera_model {short(model)}; expected pinhole")
    distortion = data.get("distortion_model", "radial-tangential")
    if distortion not in ("radial-tangential", "radtan"):
        raise DatasetError(f"{path}: distortion_model {short(distortion)}; expected radial-tangential")
    k = yaml_numbers(path, data, "distortion_coefficients", (4, 5))
    t_bs = np.array(yaml_numbers(path, data, "T_BS", 16)).reshape(4, 4)
    return make_camera(path, (w, h), (fx, fy, cx, cy), RadTanCamera, k), rigid(path, t_bs, "T_BS")


def short(value: object) -> str:
    """A value from a user's YAML as a message shows it: its repr, bounded."""
    short = reprlib.Repr()
    short.maxstring, short.maxother, short.maxlist, short.maxdict, short.maxlevel = 60, 60, 6, 4, 2
    return short.repr(value)


def make_camera(path: Path, size: tuple[int, int], intrinsics: tuple[float, ...], model, k: list[float]) -> CameraFile:
    (w, h), (fx, fy, cx, cy) = size, intrinsics
    if min(w, h) <= 0 or min(fx, fy) <= 0:
        raise DatasetError(f"{path}: image size {w}x{h} and focal lengths {fx}, {fy} must be positive")
    pinhole = PinholeCamera(w, h, fx, fy, cx, cy)
    if not any(k):
        return CameraFile(FovCamera(w, h, fx, fy, cx, cy, 0.0), "none", w, h)
    return CameraFile(model(pinhole, *k), "crop", w, h)


def rigid(path: Path, t: np.ndarray, key: str) -> np.ndarray:
    r = t[:3, :3]
    if not np.allclose(r @ r.T, np.eye(3), atol=1e-4) or not np.allclose(t[3], [0, 0, 0, 1]):
        raise DatasetError(
            f"{path}: {key} is not a rigid transform (rotation not orthonormal, or last row not 0 0 0 1)"
        )
    if np.abs(t[:3, 3]).max() > MAX_POSITION_M:
        raise DatasetError(f"{path}: {key} moves the camera {np.abs(t[:3, 3]).max():g} m; expected a rigid mount")
    return t


# ---------------------------------------------------------------------------------------------------- the layout


def recognise(root: Path) -> bool:
    """mav0/cam0/ without TUM-VI's dso/camchain.yaml."""
    return (root / CAM).is_dir() and not (root / "dso" / "camchain.yaml").exists()


# EuRoC's cam0: the radial-tangential distortion and the camera-to-body transform of the real rig (MH_01's
# sensor.yaml), the intrinsics scaled to the image size.
EUROC_DISTORTION = (-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05)
EUROC_T_BS = np.array(
    [
        [0.0148655429818, -0.999880929698, 0.00414029679422, -0.0216401454975],
        [0.999557249008, 0.0149672133247, 0.025715529948, -0.064676986768],
        [-0.0257744366974, 0.00375618835797, 0.999660727178, 0.00981073058949],
        [0.0, 0.0, 0.0, 1.0],
    ]
)
EUROC_START_NS = 1403636579763555584  # MH_01's first frame


def write_asl_frames(mav0: Path, s: Synth, cam, rate_hz: float, bits: int = 8) -> np.ndarray:
    """mav0/cam0/data/<ns>.png and data.csv; returns the frames' times in nanoseconds."""
    import cv2

    period_ns = int(round(1e9 / rate_hz))
    ns = EUROC_START_NS + period_ns * np.arange(s.frames, dtype=np.int64) + (np.arange(s.frames) % 3) * 1000
    data = mav0 / "cam0" / "data"
    data.mkdir(parents=True)
    for i, img in s.images(cam):
        cv2.imwrite(str(data / f"{ns[i]}.png"), img.astype(np.uint16) * 257 if bits == 16 else img)
    (mav0 / "cam0" / "data.csv").write_text(
        "#timestamp [ns],filename\n" + "".join(f"{v},{v}.png\n" for v in ns.tolist())
    )
    return ns


def body_rows(s: Synth, ns_frames: np.ndarray, rate_hz: float, t_body_cam: np.ndarray, keep=None) -> str:
    """ASL state rows (ns, p, q w-first, then zero velocities and biases) of the body at `rate_hz`, from a little
    before the first frame to a little after the last, at times that are not the frames' own."""
    from scipy.spatial.transform import Rotation

    from slamrun.datasets.synth import loop_fraction

    period = int(round(1e9 / rate_hz))
    ns = np.arange(ns_frames[0] - 5 * period + 1_700_000, ns_frames[-1] + 5 * period, period, dtype=np.int64)
    frac = loop_fraction(ns.astype(float), ns_frames.astype(float))
    cam = s.poses_at(s.scene, frac)
    body = cam @ np.linalg.inv(t_body_cam)
    q = Rotation.from_matrix(body[:, :3, :3]).as_quat()
    rows = []
    for k in range(len(ns)):
        if keep is not None and not keep(frac[k]):
            continue
        x, y, z = body[k, :3, 3]
        rows.append(f"{ns[k]},{x:.9f},{y:.9f},{z:.9f},{q[k, 3]:.9f},{q[k, 0]:.9f},{q[k, 1]:.9f},{q[k, 2]:.9f}")
    return "".join(r + ",0,0,0,0,0,0,0,0,0\n" for r in rows)


def write_synthetic(tmp: Path, s: Synth) -> Placed:
    """The sequence in EuRoC's layout: 20 Hz frames with nanosecond names (not quite regular), the real rig's
    distortion and T_BS, and the body's ground truth at 200 Hz on its own clock ticks."""
    w, h = s.size
    f = 0.61 * w
    pinhole = PinholeCamera(w, h, f, f * 0.997, w / 2 - 8.8, h / 2 + 8.4)
    cam = RadTanCamera(pinhole, *EUROC_DISTORTION)
    mav0 = tmp / "mav0"
    ns = write_asl_frames(mav0, s, cam, rate_hz=20.0)
    tbs = ", ".join(f"{v:.12g}" for v in EUROC_T_BS.ravel())
    (mav0 / "cam0" / "sensor.yaml").write_text(
        "# General sensor definitions.\nsensor_type: camera\ncomment: slamrun synth cam0 (EuRoC layout)\n\n"
        f"# Sensor extrinsics wrt. the body-frame.\nT_BS:\n  cols: 4\n  rows: 4\n  data: [{tbs}]\n\n"
        f"rate_hz: 20\nresolution: [{w}, {h}]\ncamera_model: pinhole\n"
        f"intrinsics: [{pinhole.fx:.9g}, {pinhole.fy:.9g}, {pinhole.cx:.9g}, {pinhole.cy:.9g}] #fu, fv, cu, cv\n"
        f"distortion_model: radial-tangential\ndistortion_coefficients: [{', '.join(map(str, EUROC_DISTORTION))}]\n"
    )
    gt = mav0 / "state_groundtruth_estimate0"
    gt.mkdir()
    header = "#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z [], "
    header += "v_RS_R_x [m s^-1], v_RS_R_y [m s^-1], v_RS_R_z [m s^-1], b_w_RS_S_x [rad s^-1], "
    header += "b_w_RS_S_y [rad s^-1], b_w_RS_S_z [rad s^-1], b_a_RS_S_x [m s^-2], b_a_RS_S_y [m s^-2], "
    header += "b_a_RS_S_z [m s^-2]\n"
    (gt / "data.csv").write_text(header + body_rows(s, ns, 200.0, EUROC_T_BS))
    return []


URL = os.environ.get("SLAMRUN_EUROC_URL", "http://robotics.ethz.ch/~asl-datasets/ijrr_euroc_mav_dataset")
EUROC_SEQUENCES = {
    "machine_hall": ["MH_01_easy", "MH_02_easy", "MH_03_medium", "MH_04_difficult", "MH_05_difficult"],
    "vicon_room1": ["V1_01_easy", "V1_02_medium", "V1_03_difficult"],
    "vicon_room2": ["V2_01_easy", "V2_02_medium", "V2_03_difficult"],
}


def _archive(name: str, base: str) -> tuple[str, str] | None:
    group = next((g for g, seqs in EUROC_SEQUENCES.items() if name in seqs), None)
    return None if group is None else (name, f"{base}/{group}/{name}/{name}.zip")


ALL_SEQUENCES = tuple(s for seqs in EUROC_SEQUENCES.values() for s in seqs)
LAYOUT = Layout(
    name="euroc",
    title="EuRoC MAV (ASL layout, cam0; body ground truth carried to the camera)",
    recognise=recognise,
    frame_list=str(FRAME_LIST),
    read=open_euroc,
    groundtruth_file=str(EUROC_GT),
    synth=write_synthetic,
    download=Download(URL, _archive, ", ".join(ALL_SEQUENCES), default=ALL_SEQUENCES),
    file_note=file_notes.euroc,
)
