"""TUM-VI, exported in the ASL layout (`dataset-room1_512_16/`): `mav0/cam0/` as EuRoC's (slamrun.datasets.euroc
reads it), the calibration `dso/camchain.yaml` (Kalibr: equidistant fisheye, T_cam_imu) and `mav0/mocap0/data.csv`
(IMU poses where the motion-capture room sees the rig: at the start and the end only), carried to the camera and
interpolated at the frames' times. Written synthetically with the real rig's fisheye and T_cam_imu, 16-bit frames;
downloaded as the site's `dataset-<room>_512_16.tar`.
"""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from slamrun.core.camera import CameraFile, EquidistantCamera, PinholeCamera
from slamrun.datasets import file_notes
from slamrun.datasets.euroc import (
    CAM,
    FRAME_LIST,
    body_rows,
    calibration_yaml,
    make_camera,
    open_asl,
    rigid,
    short,
    write_asl_frames,
    yaml_numbers,
)
from slamrun.datasets.file_notes import TUMVI_GT
from slamrun.datasets.protocol import Download, Layout, Placed
from slamrun.datasets.sequence import Sequence
from slamrun.errors import DatasetError

if TYPE_CHECKING:
    from slamrun.datasets.synth import Synth

TUMVI_CALIB = Path("dso/camchain.yaml")
NOTES = (
    "TUM-VI's ground truth covers only the parts of the sequence the motion-capture room sees; "
    "metrics are computed on the frames that have it",
)


def open_tum_vi(root: str | Path) -> Sequence:
    return open_asl(Path(root), "tum-vi", TUMVI_CALIB, TUMVI_GT, read_camchain, NOTES)


def read_camchain(path: Path) -> tuple[CameraFile, np.ndarray]:
    """TUM-VI's Kalibr camchain (cam0: equidistant fisheye, T_cam_imu) → the camera and T_imu_cam."""
    data = calibration_yaml(path)
    cam0 = data.get("cam0")
    if not isinstance(cam0, dict):
        raise DatasetError(f"{path}: no cam0 section")
    w, h = (int(v) for v in yaml_numbers(path, cam0, "resolution", 2))
    fx, fy, cx, cy = yaml_numbers(path, cam0, "intrinsics", 4)
    if cam0.get("distortion_model") != "equidistant":
        found = short(cam0.get("distortion_model"))
        raise DatasetError(f"{path}: cam0 distortion_model {found}; expected equidistant")
    k = yaml_numbers(path, cam0, "distortion_coeffs", 4)
    rows = cam0.get("T_cam_imu")
    if not (isinstance(rows, list) and len(rows) == 4 and all(isinstance(r, list) and len(r) == 4 for r in rows)):
        raise DatasetError(f"{path}: cam0 T_cam_imu: expected 4 rows of 4 numbers")
    t_cam_imu = rigid(path, np.array(rows, float), "T_cam_imu")
    return make_camera(path, (w, h), (fx, fy, cx, cy), EquidistantCamera, k), np.linalg.inv(t_cam_imu)


def recognise(root: Path) -> bool:
    """mav0/cam0/ and dso/camchain.yaml."""
    return (root / CAM).is_dir() and (root / TUMVI_CALIB).exists()


# TUM-VI's cam0 (room sequences, 512x512 equidistant) and its camera-to-IMU transform, as in its camchain.
TUMVI_DISTORTION = (0.0034823894022493434, 0.0007150348452162257, -0.0020532361418706202, 0.00020293673591811182)
TUMVI_T_CAM_IMU = np.array(
    [
        [-0.9995250378696743, 0.029615343885863205, -0.008522328211654736, 0.04727988224914392],
        [0.0075019185074052044, -0.03439736061393144, -0.9993800792498829, -0.047443232143367084],
        [-0.02989013031643309, -0.998969345370175, 0.03415885127385616, -0.0681999605066297],
        [0.0, 0.0, 0.0, 1.0],
    ]
)


def write_synthetic(tmp: Path, s: Synth) -> Placed:
    """The sequence in TUM-VI's layout: 16-bit fisheye frames at 20 Hz, the camchain, and the motion-capture
    ground truth (120 Hz, IMU frame) at the start and the end of the loop only."""
    from slamrun.datasets.synth import GT_FRACTION

    w, h = s.size
    f = 0.373 * w  # TUM-VI: 190.97 px on 512
    pinhole = PinholeCamera(w, h, f, f, w / 2 - 1.07, h / 2 + 0.89)
    cam = EquidistantCamera(pinhole, *TUMVI_DISTORTION)
    mav0 = tmp / "mav0"
    ns = write_asl_frames(mav0, s, cam, rate_hz=20.0, bits=16)
    (tmp / "dso").mkdir()
    rows = "\n".join(f"    - [{', '.join(f'{v:.15g}' for v in r)}]" for r in TUMVI_T_CAM_IMU)
    (tmp / "dso" / "camchain.yaml").write_text(
        "cam0:\n  T_cam_imu:\n" + rows + "\n  camera_model: pinhole\n"
        f"  distortion_coeffs: [{', '.join(map(str, TUMVI_DISTORTION))}]\n  distortion_model: equidistant\n"
        f"  intrinsics: [{f:.9g}, {f:.9g}, {pinhole.cx:.9g}, {pinhole.cy:.9g}]\n  resolution: [{w}, {h}]\n"
        "  rostopic: /cam0/image_raw\n"
    )
    mocap = mav0 / "mocap0"
    mocap.mkdir()
    seen = lambda frac: frac <= GT_FRACTION or frac >= 1 - GT_FRACTION  # noqa: E731  the room sees start and end
    body = body_rows(s, ns, 120.0, np.linalg.inv(TUMVI_T_CAM_IMU), keep=seen)
    body = "".join(",".join(line.split(",")[:8]) + "\n" for line in body.splitlines())
    header = "#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z []\n"
    (mocap / "data.csv").write_text(header + body)
    return []


URL = os.environ.get("SLAMRUN_TUM_VI_URL", "https://vision.in.tum.de/tumvi/exported/euroc/512_16")
TUM_VI_ROOMS = {"corridor": 5, "magistrale": 6, "outdoors": 8, "room": 6, "slides": 3}


def _archive(name: str, base: str) -> tuple[str, str] | None:
    full = name if name.startswith("dataset-") else f"dataset-{name}_512_16"
    found = re.fullmatch(r"dataset-([a-z]+)(\d+)_512_16", full)
    if found is None or not 1 <= int(found.group(2)) <= TUM_VI_ROOMS.get(found.group(1), 0):
        return None
    return full, f"{base}/{full}.tar"


LAYOUT = Layout(
    name="tum-vi",
    title="TUM-VI (ASL export, 512x512 fisheye cam0; ground truth at the start and end)",
    recognise=recognise,
    frame_list=str(FRAME_LIST),
    read=open_tum_vi,
    groundtruth_file=str(TUMVI_GT),
    synth=write_synthetic,
    download=Download(
        URL,
        _archive,
        ", ".join(f"{room}1-{n}" for room, n in TUM_VI_ROOMS.items()) + " (e.g. room1, dataset-room1_512_16)",
    ),
    file_note=file_notes.tum_vi,
)
