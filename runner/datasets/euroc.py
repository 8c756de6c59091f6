"""EuRoC MAV and TUM-VI sequences in the ASL layout: `mav0/cam0/` (data.csv with nanosecond timestamps, data/),
the first camera only.

EuRoC: `mav0/cam0/sensor.yaml` (pinhole intrinsics, radial-tangential distortion, T_BS: camera to body) and the
ground truth `mav0/state_groundtruth_estimate0/data.csv` (the body, i.e. IMU, poses at 200 Hz).
TUM-VI: `dso/camchain.yaml` (Kalibr: equidistant fisheye, T_cam_imu) and `mav0/mocap0/data.csv` (IMU poses where
the motion-capture room sees the rig: at the start and the end only).
Camera poses are body poses times the camera's extrinsics, interpolated at the frames' times.
"""

from __future__ import annotations

import reprlib
from pathlib import Path

import numpy as np

from runner.core.camera import CameraFile, EquidistantCamera, FovCamera, PinholeCamera, RadTanCamera
from runner.core.inputs import load_yaml_file
from runner.core.trajectory import Trajectory, read_euroc_csv
from runner.datasets import frames
from runner.datasets.sequence import (
    IMAGE_SUFFIXES,
    MAX_POSITION_M,
    Sequence,
    camera_problem,
    check_positions,
    check_regular,
    folder_sequence,
    interpolate_poses,
    read_text,
    transform_poses,
)
from runner.errors import DatasetError, TrajectoryFormatError

CAM = Path("mav0/cam0")
EUROC_GT = Path("mav0/state_groundtruth_estimate0/data.csv")
TUMVI_GT = Path("mav0/mocap0/data.csv")
TUMVI_CALIB = Path("dso/camchain.yaml")
GT_MAX_GAP_S = 0.02  # ground truth is interpolated between samples at most this far from a frame
MAX_NS = 2**63 - 1  # EuRoC's stamps are int64 nanoseconds


def open_euroc(root: str | Path) -> Sequence:
    return _open(Path(root), "euroc")


def open_tum_vi(root: str | Path) -> Sequence:
    return _open(Path(root), "tum-vi")


def _open(root: Path, layout: str) -> Sequence:
    if not root.is_dir():
        raise DatasetError(f"{root}: sequence folder not found")
    csv, calib = root / CAM / "data.csv", root / (CAM / "sensor.yaml" if layout == "euroc" else TUMVI_CALIB)
    gt_path = root / (EUROC_GT if layout == "euroc" else TUMVI_GT)
    problems = check_regular([csv, calib, gt_path], {csv, calib, gt_path})
    if problems:
        raise DatasetError(f"{root}: invalid {layout} sequence:\n  " + "\n  ".join(problems))
    for p, what in ((csv, "the frame list (#timestamp [ns],filename)"), (calib, "the camera calibration")):
        if not p.is_file():
            problems.append(f"{p}: missing; expected {what}")
    camera, t_body_cam = None, None
    if calib.is_file():
        try:
            camera, t_body_cam = read_sensor_yaml(calib) if layout == "euroc" else read_camchain(calib)
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
    if problems:
        raise DatasetError(f"{root}: invalid {layout} sequence:\n  " + "\n  ".join(problems))
    assert camera is not None and ns is not None and t_body_cam is not None
    times = (ns // 1_000_000_000).astype(float) + (ns % 1_000_000_000).astype(float) * 1e-9
    notes = ()
    if layout == "tum-vi":
        notes = (
            "TUM-VI's ground truth covers only the parts of the sequence the motion-capture room sees; "
            "metrics are computed on the frames that have it",
        )

    def groundtruth() -> Trajectory:
        if problem := check_regular([gt_path], {gt_path}):
            raise DatasetError(problem[0])
        try:
            body = read_euroc_csv(gt_path)
        except TrajectoryFormatError as exc:
            raise DatasetError(str(exc)) from None
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
    if not names:
        problems.append(f"{csv}: no frame listed")
        return [], None
    ns = np.array(stamps, dtype=np.int64)
    bad = np.flatnonzero(np.diff(ns) <= 0)
    if len(bad):
        problems.append(f"{csv}: timestamps not strictly increasing (row {int(bad[0]) + 2} of the frames)")
        return [], None
    return names, ns


def _yaml(path: Path) -> dict:
    """A calibration YAML, read with runner.core.inputs' bounds (size, aliases, nesting)."""
    data = load_yaml_file(path, "the camera calibration", DatasetError)
    if not isinstance(data, dict):
        raise DatasetError(f"{path}: expected a mapping of calibration keys")
    return data


def _numbers(path: Path, data: dict, key: str, count: int | tuple[int, ...]) -> list[float]:
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
        raise DatasetError(f"{path}: {key}: expected a list of {want} finite numbers, found {_short(value)}")
    return [float(v) for v in value]


def read_sensor_yaml(path: Path) -> tuple[CameraFile, np.ndarray]:
    """EuRoC's cam0/sensor.yaml → the camera (pinhole + radial-tangential; rectified with `crop`) and T_BS."""
    data = _yaml(path)
    w, h = (int(v) for v in _numbers(path, data, "resolution", 2))
    fx, fy, cx, cy = _numbers(path, data, "intrinsics", 4)
    model = data.get("camera_model", "pinhole")
    if model != "pinhole":
        raise DatasetError(f"{path}: camera_model {_short(model)}; expected pinhole")
    distortion = data.get("distortion_model", "radial-tangential")
    if distortion not in ("radial-tangential", "radtan"):
        raise DatasetError(f"{path}: distortion_model {_short(distortion)}; expected radial-tangential")
    k = _numbers(path, data, "distortion_coefficients", (4, 5))
    t_bs = np.array(_numbers(path, data, "T_BS", 16)).reshape(4, 4)
    return _camera(path, (w, h), (fx, fy, cx, cy), RadTanCamera, k), _rigid(path, t_bs, "T_BS")


def read_camchain(path: Path) -> tuple[CameraFile, np.ndarray]:
    """TUM-VI's Kalibr camchain (cam0: equidistant fisheye, T_cam_imu) → the camera and T_imu_cam."""
    data = _yaml(path)
    cam0 = data.get("cam0")
    if not isinstance(cam0, dict):
        raise DatasetError(f"{path}: no cam0 section")
    w, h = (int(v) for v in _numbers(path, cam0, "resolution", 2))
    fx, fy, cx, cy = _numbers(path, cam0, "intrinsics", 4)
    if cam0.get("distortion_model") != "equidistant":
        found = _short(cam0.get("distortion_model"))
        raise DatasetError(f"{path}: cam0 distortion_model {found}; expected equidistant")
    k = _numbers(path, cam0, "distortion_coeffs", 4)
    rows = cam0.get("T_cam_imu")
    if not (isinstance(rows, list) and len(rows) == 4 and all(isinstance(r, list) and len(r) == 4 for r in rows)):
        raise DatasetError(f"{path}: cam0 T_cam_imu: expected 4 rows of 4 numbers")
    t_cam_imu = _rigid(path, np.array(rows, float), "T_cam_imu")
    return _camera(path, (w, h), (fx, fy, cx, cy), EquidistantCamera, k), np.linalg.inv(t_cam_imu)


def _short(value: object) -> str:
    """A value from a user's YAML as a message shows it: its repr, bounded."""
    short = reprlib.Repr()
    short.maxstring, short.maxother, short.maxlist, short.maxdict, short.maxlevel = 60, 60, 6, 4, 2
    return short.repr(value)


def _camera(path: Path, size: tuple[int, int], intrinsics: tuple[float, ...], model, k: list[float]) -> CameraFile:
    (w, h), (fx, fy, cx, cy) = size, intrinsics
    if min(w, h) <= 0 or min(fx, fy) <= 0:
        raise DatasetError(f"{path}: image size {w}x{h} and focal lengths {fx}, {fy} must be positive")
    pinhole = PinholeCamera(w, h, fx, fy, cx, cy)
    if not any(k):
        return CameraFile(FovCamera(w, h, fx, fy, cx, cy, 0.0), "none", w, h)
    return CameraFile(model(pinhole, *k), "crop", w, h)


def _rigid(path: Path, t: np.ndarray, key: str) -> np.ndarray:
    r = t[:3, :3]
    if not np.allclose(r @ r.T, np.eye(3), atol=1e-4) or not np.allclose(t[3], [0, 0, 0, 1]):
        raise DatasetError(
            f"{path}: {key} is not a rigid transform (rotation not orthonormal, or last row not 0 0 0 1)"
        )
    if np.abs(t[:3, 3]).max() > MAX_POSITION_M:
        raise DatasetError(f"{path}: {key} moves the camera {np.abs(t[:3, 3]).max():g} m; expected a rigid mount")
    return t
