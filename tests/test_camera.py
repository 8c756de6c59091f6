"""Camera models against independent values, and a rendering check of the rectification."""

import math

import cv2
import numpy as np
import pytest

from slamrun.core.camera import (
    FovCamera,
    PinholeCamera,
    RadTanCamera,
    photometric_correct,
    read_camera_txt,
    rectification_maps,
    rectified_pinhole,
)
from slamrun.datasets.synth import Renderer, camera_path, fov_rays, make_scene, make_texture, pinhole_rays

# TUM-Mono's documented example calibration line (tum-mono.md).
TUM_LINE = "0.349 0.436 0.493 0.499 0.933\n1280 1024\ncrop\n640 480\n"


@pytest.fixture
def tum_cam(tmp_path):
    p = tmp_path / "camera.txt"
    p.write_text(TUM_LINE)
    return read_camera_txt(p)


def test_camera_txt_pixel_convention(tum_cam):
    c = tum_cam.camera
    assert (c.width, c.height) == (1280, 1024)
    assert c.fx == pytest.approx(0.349 * 1280) and c.fy == pytest.approx(0.436 * 1024)
    assert c.cx == pytest.approx(0.493 * 1280 - 0.5) and c.cy == pytest.approx(0.499 * 1024 - 0.5)
    assert c.omega == 0.933 and tum_cam.output_mode == "crop" and (tum_cam.out_width, tum_cam.out_height) == (640, 480)


def test_fov_distortion_formula_by_hand(tum_cam):
    c = tum_cam.camera
    xy = np.array([[0.3, -0.4]])  # r_u = 0.5
    rd = math.atan(2 * 0.5 * math.tan(0.933 / 2)) / 0.933
    np.testing.assert_allclose(c.distort(xy), xy * rd / 0.5, rtol=1e-12)
    ru = math.tan(0.5 * 0.933) / (2 * math.tan(0.933 / 2))
    np.testing.assert_allclose(c.undistort(xy), xy * ru / 0.5, rtol=1e-12)


def test_fov_round_trips(tum_cam):
    c = tum_cam.camera
    rng = np.random.default_rng(0)
    uv = rng.uniform([0, 0], [c.width - 1, c.height - 1], size=(1000, 2))
    xy = c.unproject(uv)
    beyond = ~np.isfinite(xy).all(axis=1)  # the far corners of this 148-degree lens lie beyond 90 degrees
    assert 0 < beyond.mean() < 0.1
    r_d = np.linalg.norm(c.pinhole.unproject(uv[beyond]), axis=1)
    assert (r_d * c.omega >= math.pi / 2).all()
    uv, xy = uv[~beyond], xy[~beyond]
    np.testing.assert_allclose(c.pinhole.project(c.distort(xy)), uv, atol=1e-9)
    pts = np.column_stack([xy * 3.0, np.full(len(xy), 3.0)])
    np.testing.assert_allclose(c.project(pts), uv, atol=1e-9)
    np.testing.assert_allclose(c.distort(np.zeros((1, 2))), 0)


def test_crop_rule_written_out(tum_cam):
    """The crop K computed step by step from the rule in tum-mono.md."""
    c = tum_cam.camera
    k = rectified_pinhole(c, "crop", 640, 480)
    tan2 = 2 * math.tan(c.omega / 2)
    radii = {"l": c.cx / c.fx, "r": (1279 - c.cx) / c.fx, "t": c.cy / c.fy, "b": (1023 - c.cy) / c.fy}
    tr = {k_: math.tan(v * c.omega) / tan2 for k_, v in radii.items()}
    fx = c.fx * (radii["l"] + radii["r"]) / (tr["l"] + tr["r"]) * 640 / 1280
    fy = c.fy * (radii["t"] + radii["b"]) / (tr["t"] + tr["b"]) * 480 / 1024
    assert k.fx == pytest.approx(fx, rel=1e-12) and k.fy == pytest.approx(fy, rel=1e-12)
    assert k.cx == pytest.approx(tr["l"] * fx) and k.cy == pytest.approx(tr["t"] * fy)
    # Only valid pixels: the midpoints of the output borders map inside the input image.
    border = np.array([[0, k.cy], [639, k.cy], [k.cx, 0], [k.cx, 479]])
    back = c.pinhole.project(c.distort(k.unproject(border)))
    assert (back >= -0.51).all() and (back[:, 0] <= 1279.51).all() and (back[:, 1] <= 1023.51).all()


def test_full_keeps_the_corners():
    c = FovCamera(1280, 1024, 0.5 * 1280, 0.6 * 1024, 639.5, 511.5, 0.8)  # corners within 90 degrees
    full = rectified_pinhole(c, "full", 640, 480)
    crop = rectified_pinhole(c, "crop", 640, 480)
    assert full.fx < crop.fx and full.fy < crop.fy
    corners = np.array([[0, 0], [1279, 0], [0, 1023], [1279, 1023]], float)
    out = full.project(c.unproject(corners))
    assert (out >= -1e-6).all() and (out[:, 0] <= 639 + 1e-6).all() and (out[:, 1] <= 479 + 1e-6).all()


def test_radtan_round_trip():
    cam = RadTanCamera(PinholeCamera(640, 480, 500, 500, 320, 240), k1=-0.2, k2=0.05, p1=0.001, p2=-0.002)
    xy = np.random.default_rng(1).uniform(-0.5, 0.5, size=(500, 2))
    np.testing.assert_allclose(cam.undistort(cam.distort(xy)), xy, atol=1e-9)
    # against OpenCV's own undistortPoints
    d = np.array([-0.2, 0.05, 0.001, -0.002, 0.0])
    uv = cam.pinhole.project(cam.distort(xy))
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-14)
    points = uv.reshape(-1, 1, 2)
    if hasattr(cv2, "undistortPointsIter"):  # OpenCV 4
        ocv = cv2.undistortPointsIter(points, cam.pinhole.K(), d, None, None, crit)
    else:  # OpenCV 5
        ocv = cv2.undistortPoints(points, cam.pinhole.K(), d, None, None, None, crit)
    ocv = ocv.reshape(-1, 2)
    np.testing.assert_allclose(ocv, xy, atol=1e-6)


def test_rectified_fov_render_matches_direct_pinhole_render():
    """Render through the FOV camera, rectify with slamrun.camera; render the rectified pinhole camera directly."""
    rng = np.random.default_rng(3)
    scene = make_scene("indoor", rng)
    texture = make_texture(rng, size=1024)
    fov = FovCamera(640, 480, 0.5 * 640, 0.5 * 640, 319.5, 239.5, 0.9)
    pin = rectified_pinhole(fov, "crop", 640, 480)
    rots, pos = camera_path(scene, 40)
    fov_img = Renderer(scene, texture, fov_rays(fov), (480, 640)).render(rots[10], pos[10])
    direct = Renderer(scene, texture, pinhole_rays(pin), (480, 640)).render(rots[10], pos[10])
    mx, my = rectification_maps(fov, pin)
    rect = cv2.remap(fov_img, mx, my, cv2.INTER_LINEAR)
    inner = (slice(20, -20), slice(20, -20))
    ncc = np.corrcoef(rect[inner].ravel(), direct[inner].ravel())[0, 1]
    assert ncc > 0.9, ncc  # threshold: normalised cross-correlation above 0.9
    assert np.median(np.abs(rect[inner] - direct[inner])) < 8  # grey levels
    # A wrong model (omega off by 10 %) is clearly worse: the check can fail.
    wrong = FovCamera(640, 480, 0.5 * 640, 0.5 * 640, 319.5, 239.5, 0.99)
    mx, my = rectification_maps(wrong, pin)
    bad = cv2.remap(fov_img, mx, my, cv2.INTER_LINEAR)
    assert np.corrcoef(bad[inner].ravel(), direct[inner].ravel())[0, 1] < ncc - 0.1


def test_photometric_correction_inverts_the_model():
    g_inv = 255.0 * (np.arange(256) / 255.0) ** 1.3
    vignette = np.linspace(0.5, 1.0, 100, dtype=np.float32).reshape(10, 10)
    irradiance = np.full((10, 10), 20.0, np.float32)
    exposure = 4.0
    observed = np.clip(np.rint(255 * ((exposure * vignette * irradiance) / 255) ** (1 / 1.3)), 0, 255).astype(np.uint8)
    b = photometric_correct(observed, g_inv, vignette, exposure)
    np.testing.assert_allclose(b, irradiance, rtol=0.05)
