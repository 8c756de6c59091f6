"""The synthetic renderer (tiles, culled boxes, 8-bit look-ups) against a plain per-pixel ray caster."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from slamrun.core.camera import FovCamera, rectified_pinhole
from slamrun.datasets.synth import Renderer, camera_path, fov_rays, make_scene, make_texture, pinhole_rays


def reference_faces_and_points(scene, rays_cam: np.ndarray, rot: np.ndarray, pos: np.ndarray):
    """For every ray: the face seen (6 per box: 2 * axis + side) and the hit point, by testing the room
    and every box on every ray in float64. No culling, no tiles."""
    w = rays_cam @ rot.T
    n = len(w)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / w
        lo_t, hi_t = (scene.room_lo - pos) * inv, (scene.room_hi - pos) * inv
        exits = np.maximum(lo_t, hi_t)  # the room is seen from inside: leave through the farther wall
        axis = exits.argmin(axis=1)
        t = exits[np.arange(n), axis]
        face = 2 * axis + (w[np.arange(n), axis] > 0)
        for i, (blo, bhi) in enumerate(scene.boxes):
            a, b = (blo - pos) * inv, (bhi - pos) * inv
            near, far = np.minimum(a, b), np.maximum(a, b)
            tmin, tfar = near.max(axis=1), far.min(axis=1)
            hit = (tmin > 0) & (tmin <= tfar) & (tmin < t)
            ax = near.argmax(axis=1)
            t = np.where(hit, tmin, t)
            face = np.where(hit, 6 * (i + 1) + 2 * ax + (w[np.arange(n), ax] < 0), face)
    return face, pos + w * t[:, None]


def check_against_reference(renderer: Renderer, scene, rays: np.ndarray, rot, pos, shape) -> None:
    renderer.render(rot, pos)
    face, points = reference_faces_and_points(scene, rays, rot, pos)
    got = renderer._face.ravel()
    agree = got == face
    # float32 against float64: only rays grazing an edge may pick the neighbouring face
    assert agree.mean() > 0.999, agree.mean()
    axis = (face % 6) // 2
    u = np.where(axis == 0, points[:, 1], points[:, 0])
    tpm = scene.texels_per_m
    expected_x = u * tpm + renderer._face_offset_x[face]
    err = np.abs(renderer._map_x.ravel() - expected_x)[agree]
    assert np.quantile(err, 0.999) < 0.05, np.quantile(err, 0.999)  # texels


@pytest.fixture(scope="module")
def scene_and_texture():
    rng = np.random.default_rng(4)
    return make_scene("indoor", rng), make_texture(rng, size=512)


def test_fov_render_matches_reference_along_the_path(scene_and_texture):
    scene, texture = scene_and_texture
    cam = FovCamera(320, 240, 176.0, 176.0, 159.5, 119.5, 0.8)
    rays = fov_rays(cam)
    renderer = Renderer(scene, texture, rays, (240, 320))
    rots, pos = camera_path(scene, 12)
    for i in range(0, 12, 3):
        check_against_reference(renderer, scene, rays, rots[i], pos[i], (240, 320))


def test_pinhole_render_and_a_box_reaching_behind_the_camera(scene_and_texture):
    scene, texture = scene_and_texture
    pin = rectified_pinhole(FovCamera(320, 240, 176.0, 176.0, 159.5, 119.5, 0.8), "crop", 320, 240)
    rays = pinhole_rays(pin)
    renderer = Renderer(scene, texture, rays, (240, 320))
    blo, bhi = scene.boxes[0]
    # Beside box 0, 5 cm from its face, looking along it: part of the box is behind the camera.
    pos = np.array([bhi[0] + 0.05, (blo[1] + bhi[1]) / 2, (blo[2] + bhi[2]) / 2])
    look = Rotation.from_euler("y", 80, degrees=True) * Rotation.from_euler("x", -90, degrees=True)
    check_against_reference(renderer, scene, rays, look.as_matrix(), pos, (240, 320))


def test_rays_pointing_backwards_are_not_culled(scene_and_texture):
    """A lens wider than 180 degrees: some rays have z <= 0, so blocks cannot be bounded in x/z, y/z."""
    scene, texture = scene_and_texture
    az, el = np.meshgrid(np.linspace(-1.9, 1.9, 96), np.linspace(-1.2, 1.2, 64))
    rays = np.column_stack(
        [np.sin(az).ravel() * np.cos(el).ravel(), np.sin(el).ravel(), (np.cos(az) * np.cos(el)).ravel()]
    )
    assert (rays[:, 2] < 0).any()
    renderer = Renderer(scene, texture, rays, (64, 96))
    rots, pos = camera_path(scene, 8)
    for i in (0, 5):
        check_against_reference(renderer, scene, rays, rots[i], pos[i], (64, 96))
