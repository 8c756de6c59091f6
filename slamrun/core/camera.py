"""Camera models: FOV (ATAN) of Devernay and Faugeras as used by TUM-Mono, pinhole, radial-tangential.

Pixel convention: a pixel's centre has integer coordinates, so camera.txt's relative cx becomes
cx * width - 0.5 in pixels (and back with + 0.5).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from slamrun.core.inputs import read_bounded
from slamrun.errors import DatasetError

MAX_SIDE = 16384  # pixels: no camera's image (or rectified view) is wider or taller
MIN_INSIDE = 0.5  # a cropped (or unrectified) view samples the frame for at least this share of its pixels


@dataclass(frozen=True)
class PinholeCamera:
    width: int
    height: int
    fx: float
    fy: float
    cx: float  # pixels, pixel-centre convention
    cy: float

    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0, self.cx], [0, self.fy, self.cy], [0, 0, 1.0]])

    def project(self, xy: np.ndarray) -> np.ndarray:
        """Normalised image-plane points (N, 2) → pixels."""
        return np.column_stack([self.fx * xy[:, 0] + self.cx, self.fy * xy[:, 1] + self.cy])

    def unproject(self, uv: np.ndarray) -> np.ndarray:
        return np.column_stack([(uv[:, 0] - self.cx) / self.fx, (uv[:, 1] - self.cy) / self.fy])

    def camera_txt(self) -> str:
        """A DSO-style camera.txt for this pinhole camera (relative values, no distortion, no rectification)."""
        w, h = self.width, self.height
        rel = (self.fx / w, self.fy / h, (self.cx + 0.5) / w, (self.cy + 0.5) / h)
        return f"{rel[0]:.12g} {rel[1]:.12g} {rel[2]:.12g} {rel[3]:.12g} 0\n{w} {h}\nnone\n{w} {h}\n"


@dataclass(frozen=True)
class FovCamera:
    """FOV model: r_d = atan(2 r_u tan(omega/2)) / omega on the normalised radius."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    omega: float

    @property
    def pinhole(self) -> PinholeCamera:
        return PinholeCamera(self.width, self.height, self.fx, self.fy, self.cx, self.cy)

    def distort(self, xy: np.ndarray) -> np.ndarray:
        """Undistorted normalised points → distorted normalised points."""
        if self.omega == 0:
            return xy
        r_u = np.linalg.norm(xy, axis=1)
        r_d = np.arctan(2.0 * r_u * math.tan(self.omega / 2.0)) / self.omega
        factor = np.where(r_u > 1e-12, r_d / np.maximum(r_u, 1e-12), 2.0 * math.tan(self.omega / 2.0) / self.omega)
        return xy * factor[:, None]

    def undistort(self, xy: np.ndarray) -> np.ndarray:
        """Distorted normalised points → undistorted normalised points.

        Points with r_d * omega >= pi/2 lie at or beyond 90 degrees off-axis and have no pinhole image: NaN.
        """
        if self.omega == 0:
            return xy
        r_d = np.linalg.norm(xy, axis=1)
        with np.errstate(invalid="ignore"):
            r_u = np.where(r_d * self.omega < math.pi / 2, np.tan(r_d * self.omega), np.nan) / (
                2.0 * math.tan(self.omega / 2.0)
            )
        factor = np.where(r_d > 1e-12, r_u / np.maximum(r_d, 1e-12), self.omega / (2.0 * math.tan(self.omega / 2.0)))
        return xy * factor[:, None]

    def project(self, points_cam: np.ndarray) -> np.ndarray:
        """3-D points in the camera frame (N, 3), z forward → pixels (N, 2)."""
        xy = points_cam[:, :2] / points_cam[:, 2:3]
        return self.pinhole.project(self.distort(xy))

    def unproject(self, uv: np.ndarray) -> np.ndarray:
        """Pixels → undistorted normalised image-plane points (rays with z = 1)."""
        return self.undistort(self.pinhole.unproject(uv))

    def camera_txt_line(self) -> str:
        w, h = self.width, self.height
        rel = (self.fx / w, self.fy / h, (self.cx + 0.5) / w, (self.cy + 0.5) / h, self.omega)
        return " ".join(f"{v:.12g}" for v in rel)


class _DistortedPinhole:
    """What every distorted camera model shares (a mixin of the models below, which give `pinhole`, `distort` and
    `undistort`): its size, projection and unprojection."""

    pinhole: PinholeCamera

    @property
    def width(self) -> int:
        return self.pinhole.width

    @property
    def height(self) -> int:
        return self.pinhole.height

    def project(self, points_cam: np.ndarray) -> np.ndarray:
        """3-D points in the camera frame (N, 3), z forward → pixels (N, 2)."""
        return self.pinhole.project(self.distort(points_cam[:, :2] / points_cam[:, 2:3]))

    def unproject(self, uv: np.ndarray) -> np.ndarray:
        """Pixels → undistorted normalised image-plane points (rays with z = 1)."""
        return self.undistort(self.pinhole.unproject(uv))


@dataclass(frozen=True)
class RadTanCamera(_DistortedPinhole):
    """Pinhole with OpenCV radial-tangential distortion k1 k2 p1 p2 k3 (EuRoC, TUM RGB-D)."""

    pinhole: PinholeCamera
    k1: float = 0.0
    k2: float = 0.0
    p1: float = 0.0
    p2: float = 0.0
    k3: float = 0.0

    def distort(self, xy: np.ndarray) -> np.ndarray:
        x, y = xy[:, 0], xy[:, 1]
        r2 = x * x + y * y
        radial = 1 + self.k1 * r2 + self.k2 * r2**2 + self.k3 * r2**3
        xd = x * radial + 2 * self.p1 * x * y + self.p2 * (r2 + 2 * x * x)
        yd = y * radial + self.p1 * (r2 + 2 * y * y) + 2 * self.p2 * x * y
        return np.column_stack([xd, yd])

    def undistort(self, xy: np.ndarray, iterations: int = 20) -> np.ndarray:
        """Fixed-point inversion of `distort` (accurate for moderate distortion)."""
        und = xy.copy()
        for _ in range(iterations):
            und = und + (xy - self.distort(und))
        return und


@dataclass(frozen=True)
class EquidistantCamera(_DistortedPinhole):
    """Pinhole with the equidistant (Kannala-Brandt) fisheye distortion k1..k4 of OpenCV's fisheye module and
    Kalibr's `equidistant` model (TUM-VI): r_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8)."""

    pinhole: PinholeCamera
    k1: float = 0.0
    k2: float = 0.0
    k3: float = 0.0
    k4: float = 0.0

    def _radius(self, theta: np.ndarray) -> np.ndarray:
        t2 = theta * theta
        return theta * (1 + t2 * (self.k1 + t2 * (self.k2 + t2 * (self.k3 + t2 * self.k4))))

    def distort(self, xy: np.ndarray) -> np.ndarray:
        r = np.linalg.norm(xy, axis=1)
        theta = np.arctan(r)
        factor = np.where(r > 1e-12, self._radius(theta) / np.maximum(r, 1e-12), 1.0)
        return xy * factor[:, None]

    def undistort(self, xy: np.ndarray, iterations: int = 20) -> np.ndarray:
        """Newton's method on theta; points at or beyond 90 degrees off-axis have no pinhole image: NaN."""
        r_d = np.linalg.norm(xy, axis=1)
        theta = np.minimum(r_d, math.pi / 2)
        for _ in range(iterations):
            t2 = theta * theta
            f = self._radius(theta) - r_d
            df = 1 + t2 * (3 * self.k1 + t2 * (5 * self.k2 + t2 * (7 * self.k3 + t2 * 9 * self.k4)))
            theta = theta - f / df
        with np.errstate(invalid="ignore"):
            r_u = np.where((theta >= 0) & (theta < math.pi / 2 - 1e-6), np.tan(theta), np.nan)
        factor = np.where(r_d > 1e-12, r_u / np.maximum(r_d, 1e-12), 1.0)
        return xy * factor[:, None]


CameraModel = FovCamera | RadTanCamera | EquidistantCamera


@dataclass(frozen=True)
class CameraFile:
    """A parsed TUM-Mono camera.txt: the input camera and the requested output rectification."""

    camera: CameraModel  # FOV for TUM-Mono; other datasets' readers give their own model
    output_mode: str  # crop | full | none | explicit
    out_width: int
    out_height: int
    explicit: tuple[float, ...] | None = None


def read_camera_txt(path: str | Path) -> CameraFile:
    """Parse a TUM-Mono camera.txt (4 lines; an optional model name such as `FOV` may lead line 1)."""
    path = Path(path)
    if not (path.exists() or path.is_symlink()):
        raise DatasetError(f"{path}: missing; expected the FOV calibration (4 lines)")
    try:
        data = read_bounded(path, 2**16, "the camera calibration", DatasetError)
        lines = [ln.split() for ln in data.decode("ascii").splitlines() if ln.strip()]
    except UnicodeDecodeError as exc:
        raise DatasetError(
            f"{path}: not a text file (byte {exc.start} is not ASCII); expected the FOV calibration as 4 text lines "
            "'fx fy cx cy omega', 'width height', 'crop|full|none', 'width height'"
        ) from None
    if len(lines) < 4:
        raise DatasetError(f"{path}: {len(lines)} lines, expected 4 (intrinsics, input size, mode, output size)")
    first = lines[0]
    if first and first[0].isalpha() and first[0].lower() not in ("nan", "inf", "infinity"):
        if first[0].lower() not in ("fov", "pinhole"):
            raise DatasetError(f"{path}:1: camera model {first[0]!r} not supported; expected FOV or Pinhole")
        first = first[1:]
    try:
        vals = [float(v) for v in first]
        w, h = (int(v) for v in lines[1][:2])
        ow, oh = (int(v) for v in lines[3][:2])
    except ValueError as exc:
        raise DatasetError(f"{path}: cannot parse numbers ({exc}); expected 'fx fy cx cy omega' and sizes") from None
    if len(vals) == 4:
        vals.append(0.0)
    if len(vals) != 5:
        raise DatasetError(f"{path}:1: {len(vals)} values, expected 'fx fy cx cy omega'")
    if not all(math.isfinite(v) for v in vals):
        raise DatasetError(f"{path}:1: {' '.join(first)}: every value must be a finite number (no nan or inf)")
    if min(w, h, ow, oh) <= 0 or max(w, h, ow, oh) > MAX_SIDE:
        raise DatasetError(f"{path}: image sizes must be 1 to {MAX_SIDE} pixels (input {w}x{h}, output {ow}x{oh})")
    fx, fy, cx, cy, omega = vals
    if cx < 1 and cy < 1:  # relative to the image size
        fx, fy, cx, cy = fx * w, fy * h, cx * w - 0.5, cy * h - 0.5
    mode_tokens = lines[2]
    explicit = None
    if len(mode_tokens) == 5:
        try:
            explicit = tuple(float(v) for v in mode_tokens)
        except ValueError:
            raise DatasetError(f"{path}:3: {' '.join(mode_tokens)}: expected 5 numbers or crop, full, none") from None
        if not all(math.isfinite(v) for v in explicit):
            raise DatasetError(f"{path}:3: every value must be a finite number")
        mode = "explicit"
    else:
        mode = mode_tokens[0].lower()
        if mode not in ("crop", "full", "none"):
            raise DatasetError(f"{path}:3: output mode {mode_tokens[0]!r}; expected crop, full, none or 5 numbers")
    return CameraFile(FovCamera(w, h, fx, fy, cx, cy, omega), mode, ow, oh, explicit)


def scaled_camera_file(cam: CameraFile, width: int, height: int) -> CameraFile:
    """The same camera for its frames resized to `width` x `height`: focal lengths and principal point scaled with
    the image (pixel-centre convention), distortion unchanged (it acts on normalised coordinates), the output size
    scaled alike. An explicit output rule (absolute numbers) has no scaled form: DatasetError."""
    if cam.output_mode == "explicit":
        raise DatasetError("a camera with an explicit output rule cannot be scaled; use crop, full or none")
    model = cam.camera
    sx, sy = width / model.width, height / model.height

    def pin(c: PinholeCamera) -> PinholeCamera:
        return PinholeCamera(width, height, c.fx * sx, c.fy * sy, (c.cx + 0.5) * sx - 0.5, (c.cy + 0.5) * sy - 0.5)

    if isinstance(model, FovCamera):
        p = pin(model.pinhole)
        scaled: CameraModel = FovCamera(width, height, p.fx, p.fy, p.cx, p.cy, model.omega)
    else:
        scaled = dataclasses.replace(model, pinhole=pin(model.pinhole))
    out = (max(1, round(cam.out_width * sx)), max(1, round(cam.out_height * sy)))
    return CameraFile(scaled, cam.output_mode, out[0], out[1], None)


def write_camera_txt(path: str | Path, cam: FovCamera, mode: str = "crop", out_size: tuple[int, int] = (640, 480)):
    Path(path).write_text(f"{cam.camera_txt_line()}\n{cam.width} {cam.height}\n{mode}\n{out_size[0]} {out_size[1]}\n")


def rectified_pinhole(cam: CameraModel, mode: str, out_width: int, out_height: int) -> PinholeCamera:
    """The pinhole camera of the rectified output (`crop`: only valid pixels; `full`: the whole view)."""
    if not isinstance(cam, FovCamera):
        return _rectified_numeric(cam, mode, out_width, out_height)
    if mode == "none":
        return PinholeCamera(cam.width, cam.height, cam.fx, cam.fy, cam.cx, cam.cy)
    if cam.omega == 0:
        sx, sy = out_width / cam.width, out_height / cam.height
        return PinholeCamera(
            out_width, out_height, cam.fx * sx, cam.fy * sy, (cam.cx + 0.5) * sx - 0.5, (cam.cy + 0.5) * sy - 0.5
        )
    if mode == "crop":
        # Radii of the border midpoints, in normalised distorted coordinates, and their undistorted values.
        left = cam.cx / cam.fx
        right = (cam.width - 1 - cam.cx) / cam.fx
        top = cam.cy / cam.fy
        bottom = (cam.height - 1 - cam.cy) / cam.fy
        tan2 = 2.0 * math.tan(cam.omega / 2.0)
        t_left, t_right, t_top, t_bottom = (math.tan(r * cam.omega) / tan2 for r in (left, right, top, bottom))
        fx = cam.fx * (left + right) / (t_left + t_right) * out_width / cam.width
        fy = cam.fy * (top + bottom) / (t_top + t_bottom) * out_height / cam.height
        return PinholeCamera(out_width, out_height, fx, fy, t_left * fx, t_top * fy)
    if mode == "full":
        # Undistort the whole image border; the output spans its extent.
        n = 200
        u = np.linspace(0, cam.width - 1, n)
        v = np.linspace(0, cam.height - 1, n)
        border = np.concatenate(
            [
                np.column_stack([u, np.zeros(n)]),
                np.column_stack([u, np.full(n, cam.height - 1.0)]),
                np.column_stack([np.zeros(n), v]),
                np.column_stack([np.full(n, cam.width - 1.0), v]),
            ]
        )
        und = cam.unproject(border)
        und = und[np.isfinite(und).all(axis=1)]  # border points beyond 90 degrees cannot be kept
        (xmin, ymin), (xmax, ymax) = und.min(axis=0), und.max(axis=0)
        fx = (out_width - 1) / (xmax - xmin)
        fy = (out_height - 1) / (ymax - ymin)
        return PinholeCamera(out_width, out_height, fx, fy, -xmin * fx, -ymin * fy)
    raise ValueError(f"unknown rectification mode {mode!r}; expected crop, full or none")


def _rectified_numeric(cam: CameraModel, mode: str, out_width: int, out_height: int) -> PinholeCamera:
    """The rectified pinhole of any model from its undistorted image border: `full` spans the whole border,
    `crop` keeps the largest centred rectangle inside it (only valid pixels), `none` keeps the intrinsics."""
    p = cam.pinhole
    if mode == "none":
        return PinholeCamera(out_width, out_height, p.fx, p.fy, p.cx, p.cy)
    n = 400
    u, v = np.linspace(0, cam.width - 1, n), np.linspace(0, cam.height - 1, n)
    top, bottom = (
        cam.unproject(np.column_stack([u, np.zeros(n)])),
        cam.unproject(np.column_stack([u, np.full(n, cam.height - 1.0)])),
    )
    left, right = (
        cam.unproject(np.column_stack([np.zeros(n), v])),
        cam.unproject(np.column_stack([np.full(n, cam.width - 1.0), v])),
    )
    if mode == "full":
        und = np.concatenate([top, bottom, left, right])
        und = und[np.isfinite(und).all(axis=1)]
        (xmin, ymin), (xmax, ymax) = und.min(axis=0), und.max(axis=0)
    elif mode == "crop":
        xmin, xmax = np.nanmax(left[:, 0]), np.nanmin(right[:, 0])
        ymin, ymax = np.nanmax(top[:, 1]), np.nanmin(bottom[:, 1])
    else:
        raise ValueError(f"unknown rectification mode {mode!r}; expected crop, full or none")
    # one focal length for both axes (square pixels): the larger for crop (all inside), the smaller for full
    fx, fy = (out_width - 1) / (xmax - xmin), (out_height - 1) / (ymax - ymin)
    f = max(fx, fy) if mode == "crop" else min(fx, fy)
    cx = (out_width - 1) / 2 - f * (xmin + xmax) / 2
    cy = (out_height - 1) / 2 - f * (ymin + ymax) / 2
    return PinholeCamera(out_width, out_height, float(f), float(f), float(cx), float(cy))


@functools.lru_cache(maxsize=256)
def rectification_problem(cam: CameraFile) -> str | None:
    """Why a calibration cannot give a usable view, or None: a size beyond 1..MAX_SIDE, a focal length that is not
    positive, a rectified pinhole or rectification maps that are not finite (degenerate distortion, a focal length
    of 1e-300), or, for `crop` (and `explicit`, rectified as crop) and `none`, a view that samples outside the frame
    for more than half of its pixels. Checked on a 33x33 grid of the view: cheap enough for every validation."""
    src = cam.camera
    p = src.pinhole
    if not (0 < src.width <= MAX_SIDE and 0 < src.height <= MAX_SIDE):
        return f"image size {src.width}x{src.height}; expected 1 to {MAX_SIDE} pixels a side"
    if not (0 < cam.out_width <= MAX_SIDE and 0 < cam.out_height <= MAX_SIDE):
        return f"output size {cam.out_width}x{cam.out_height}; expected 1 to {MAX_SIDE} pixels a side"
    if not all(math.isfinite(v) for v in (p.fx, p.fy, p.cx, p.cy)) or min(p.fx, p.fy) <= 0:
        return f"focal lengths {p.fx:g}, {p.fy:g}, centre {p.cx:g}, {p.cy:g}: expected finite, positive focal lengths"
    mode = "crop" if cam.output_mode == "explicit" else cam.output_mode
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # numpy's "All-NaN slice": the values are checked below
        try:
            dst = rectified_pinhole(src, mode, cam.out_width, cam.out_height)
        except (ValueError, ZeroDivisionError, OverflowError):
            dst = None
        values = (dst.fx, dst.fy, dst.cx, dst.cy) if dst is not None else (math.nan,) * 4
        if not all(math.isfinite(v) for v in values) or min(values[:2]) <= 0:
            return (
                "the camera cannot be rectified: the rectified pinhole is not finite "
                f"(fx {values[0]:g}, fy {values[1]:g}, cx {values[2]:g}, cy {values[3]:g}); check its intrinsics and "
                "distortion"
            )
        assert dst is not None
        u, v = np.meshgrid(np.linspace(0, dst.width - 1, 33), np.linspace(0, dst.height - 1, 33))
        uv = src.pinhole.project(src.distort(dst.unproject(np.column_stack([u.ravel(), v.ravel()]))))
    if not np.isfinite(uv).all():
        return "the camera cannot be rectified: its rectification maps are not finite; check its distortion"
    inside = np.mean(
        (uv[:, 0] >= -0.5) & (uv[:, 0] <= src.width - 0.5) & (uv[:, 1] >= -0.5) & (uv[:, 1] <= src.height - 0.5)
    )
    if mode in ("crop", "none") and inside < MIN_INSIDE:
        return (
            f"the camera cannot be rectified: the {mode} view samples outside the frame for {100 * (1 - inside):.0f}% "
            f"of its pixels (at most {100 * (1 - MIN_INSIDE):.0f}%); check its intrinsics and distortion"
        )
    return None


def rectification_maps(src: CameraModel, dst: PinholeCamera) -> tuple[np.ndarray, np.ndarray]:
    """float32 maps for cv2.remap: for each output pixel, where to sample the input image."""
    u, v = np.meshgrid(np.arange(dst.width, dtype=float), np.arange(dst.height, dtype=float))
    xy = dst.unproject(np.column_stack([u.ravel(), v.ravel()]))
    uv = src.pinhole.project(src.distort(xy))
    return (
        uv[:, 0].reshape(dst.height, dst.width).astype(np.float32),
        uv[:, 1].reshape(dst.height, dst.width).astype(np.float32),
    )


def photometric_correct(
    image: np.ndarray, inverse_response: np.ndarray, vignette: np.ndarray, exposure_ms: float
) -> np.ndarray:
    """Irradiance B = G^-1(I) / (t V(x)) as float32; G^-1 given for pixel values 0..255."""
    g_inv = np.asarray(inverse_response, np.float32)
    return g_inv[image] / (np.float32(exposure_ms) * np.maximum(vignette.astype(np.float32), 1e-3))
