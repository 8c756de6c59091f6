"""A synthetic sequence in exactly the TUM-Mono layout, with known camera-to-world poses.

The scene is a textured room (or courtyard) with boxes in the middle; the camera circles them once,
looking at them, so the path closes a loop and start and end see the same place. Frames are ray-cast
through the FOV camera written to camera.txt, with a vignette, a response curve and per-frame exposure
written to vignette.png, pcalib.txt and times.txt. Deterministic for a seed.
"""

from __future__ import annotations

import io
import math
import zipfile
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from runner.camera import FovCamera, PinholeCamera, write_camera_txt

GAMMA = 1.25  # response G(x) = 255 (x/255)^(1/GAMMA); pcalib holds G^-1
FPS = 30.0
GT_FRACTION = 0.2  # first and last 20 % of the frames carry ground truth


@dataclass(frozen=True)
class Scene:
    room_lo: np.ndarray
    room_hi: np.ndarray
    boxes: tuple[tuple[np.ndarray, np.ndarray], ...]
    texels_per_m: float
    path_radii: tuple[float, float]
    cam_height: float
    look_at: np.ndarray


def make_scene(kind: str, rng: np.random.Generator) -> Scene:
    scale = {"indoor": 1.0, "outdoor": 5.0}[kind]
    boxes = []
    for _ in range(6):
        c = rng.uniform(-0.8, 0.8, size=2)
        half = rng.uniform(0.12, 0.35, size=2)
        height = rng.uniform(0.4, 1.8)
        boxes.append((np.array([*(c - half), 0.0]) * scale, np.array([*(c + half), height]) * scale))
    return Scene(
        room_lo=np.array([-4.0, -3.5, 0.0]) * scale,
        room_hi=np.array([4.0, 3.5, 3.0]) * scale,
        boxes=tuple(boxes),
        texels_per_m=300.0 / scale,
        path_radii=(2.3 * scale, 1.9 * scale),
        cam_height=1.3 * scale,
        look_at=np.array([0.0, 0.0, 0.7]) * scale,
    )


def make_texture(rng: np.random.Generator, size: int = 2048) -> np.ndarray:
    """Rich multi-scale texture with sharp edges and contrast of tens of grey levels."""
    tex = np.full((size, size), 128.0, np.float32)
    for cell, amp in ((256, 40), (64, 30), (16, 22), (4, 10)):
        grid = rng.uniform(-1, 1, size=(size // cell, size // cell)).astype(np.float32)
        tex += amp * cv2.resize(grid, (size, size), interpolation=cv2.INTER_NEAREST)
    for _ in range(1500):
        colour = float(rng.uniform(20, 235))
        x, y = (int(v) for v in rng.integers(0, size, 2))
        r = int(rng.integers(4, 60))
        if rng.random() < 0.5:
            cv2.rectangle(tex, (x, y), (x + r, y + int(rng.integers(4, 60))), colour, -1)
        else:
            cv2.circle(tex, (x, y), r // 2, colour, -1)
    tex = cv2.GaussianBlur(tex, (0, 0), 0.7)
    return np.clip(tex, 10, 245).astype(np.float32)


def camera_path(scene: Scene, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Camera-to-world rotations (n, 3, 3) and positions (n, 3): one smooth loop around the boxes."""
    phase = 2 * np.pi * np.arange(n) / max(n - 1, 1)
    a, b = scene.path_radii
    pos = np.column_stack([a * np.cos(phase), b * np.sin(phase), scene.cam_height + 0.1 * a / 2.3 * np.sin(3 * phase)])
    target = scene.look_at + np.column_stack([0.3 * np.sin(2 * phase), 0.3 * np.cos(phase), 0.2 * np.sin(phase)])
    fwd = target - pos
    fwd /= np.linalg.norm(fwd, axis=1, keepdims=True)
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right, axis=1, keepdims=True)
    down = np.cross(fwd, right)
    rot = np.stack([right, down, fwd], axis=2)  # columns: camera x, y, z in world
    roll = Rotation.from_rotvec(np.outer(0.05 * np.sin(2 * phase), [0, 0, 1])).as_matrix()
    return rot @ roll, pos


class Renderer:
    """Ray-casts the scene for a fixed set of camera rays (one per pixel)."""

    def __init__(self, scene: Scene, texture: np.ndarray, rays_cam: np.ndarray, shape: tuple[int, int]):
        self.scene = scene
        self.texture = texture
        self.rays = rays_cam.astype(np.float32)
        self.ray_x, self.ray_y, self.ray_z = (np.ascontiguousarray(self.rays[:, k]) for k in range(3))
        self.ray_norm = np.linalg.norm(self.rays, axis=1).astype(np.float32)
        self.shape = shape
        rng = np.random.default_rng(99)
        n_faces = 6 * (1 + len(scene.boxes))
        self.offsets = rng.uniform(0, texture.shape[0], size=(n_faces, 2)).astype(np.float32)
        self.shade = rng.uniform(0.75, 1.0, size=n_faces).astype(np.float32)

    def render(self, rot: np.ndarray, pos: np.ndarray) -> np.ndarray:
        """Irradiance-like image in 0..255 (float32) seen from camera-to-world (rot, pos).

        Structure-of-arrays ray casting (one contiguous float32 array per coordinate); each box is only
        tested on the rays inside its bounding cone.
        """
        rot = rot.astype(np.float32)
        cx, cy, cz = self.ray_x, self.ray_y, self.ray_z
        w = [rot[k, 0] * cx + rot[k, 1] * cy + rot[k, 2] * cz for k in range(3)]  # world ray components
        o = pos.astype(np.float32)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            inv = [np.float32(1.0) / wk for wk in w]
            lo, hi = self.scene.room_lo.astype(np.float32), self.scene.room_hi.astype(np.float32)
            # Room, seen from inside: the nearest wall along each axis.
            t = np.full(len(cx), np.inf, np.float32)
            face = np.zeros(len(cx), np.int32)
            for k in range(3):
                pos_dir = w[k] > 0
                tk = np.where(pos_dir, (hi[k] - o[k]) * inv[k], (lo[k] - o[k]) * inv[k])
                tk[~(tk > 0)] = np.inf  # a ray parallel to a wall never meets it
                closer = tk < t
                t[closer] = tk[closer]
                face[closer] = 2 * k + pos_dir[closer]
            # Boxes, seen from outside: slab test on the rays of the box's bounding cone.
            for i, (blo, bhi) in enumerate(self.scene.boxes):
                centre = ((blo + bhi) / 2).astype(np.float32)
                radius = float(np.linalg.norm(bhi - blo) / 2)
                v = centre - o
                dist = float(np.linalg.norm(v))
                if dist > radius:
                    cos_max = np.sqrt(1.0 - (radius / dist) ** 2)
                    dot = w[0] * v[0] + w[1] * v[1] + w[2] * v[2]
                    idx = np.flatnonzero(dot > np.float32(cos_max * dist) * self.ray_norm)
                else:
                    idx = np.arange(len(cx))
                if len(idx) == 0:
                    continue
                wi = [wk[idx] for wk in w]
                ii = [ik[idx] for ik in inv]
                near, far = [], []
                for k in range(3):
                    a = (np.float32(blo[k]) - o[k]) * ii[k]
                    b = (np.float32(bhi[k]) - o[k]) * ii[k]
                    near.append(np.minimum(a, b))
                    far.append(np.maximum(a, b))
                tmin = np.maximum(np.maximum(near[0], near[1]), near[2])
                tfar = np.minimum(np.minimum(far[0], far[1]), far[2])
                hit = (tmin > 0) & (tmin <= tfar) & (tmin < t[idx])
                if not hit.any():
                    continue
                tm = tmin[hit]
                axis = np.where(near[0][hit] == tm, 0, np.where(near[1][hit] == tm, 1, 2))
                sign = np.where(np.choose(axis, [wi[0][hit], wi[1][hit], wi[2][hit]]) < 0, 1, 0)
                sel = idx[hit]
                t[sel] = tm
                face[sel] = 6 * (i + 1) + axis * 2 + sign
        axis = (face % 6) // 2
        px, py, pz = (o[k] + w[k] * t for k in range(3))
        u = np.where(axis == 0, py, px)
        v = np.where(axis == 2, py, pz)
        tpm = np.float32(self.scene.texels_per_m)
        map_x = (u * tpm + self.offsets[face, 0]).reshape(self.shape)
        map_y = (v * tpm + self.offsets[face, 1]).reshape(self.shape)
        img = cv2.remap(self.texture, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
        return img * self.shade[face].reshape(self.shape)


def default_camera(width: int, height: int) -> FovCamera:
    fx = 0.55 * width
    return FovCamera(width, height, fx, fx, width / 2 - 0.5, height / 2 - 0.5, 0.8)


def fov_rays(cam: FovCamera) -> np.ndarray:
    u, v = np.meshgrid(np.arange(cam.width, dtype=float), np.arange(cam.height, dtype=float))
    xy = cam.unproject(np.column_stack([u.ravel(), v.ravel()]))
    return np.column_stack([xy, np.ones(len(xy))])


def pinhole_rays(cam: PinholeCamera) -> np.ndarray:
    u, v = np.meshgrid(np.arange(cam.width, dtype=float), np.arange(cam.height, dtype=float))
    xy = cam.unproject(np.column_stack([u.ravel(), v.ravel()]))
    return np.column_stack([xy, np.ones(len(xy))])


def vignette_image(cam: FovCamera) -> np.ndarray:
    u, v = np.meshgrid(np.arange(cam.width), np.arange(cam.height))
    r2 = ((u - cam.cx) / cam.width) ** 2 + ((v - cam.cy) / cam.height) ** 2
    return (1.0 - 0.6 * r2 / r2.max()).astype(np.float32)


def response(irradiance: np.ndarray) -> np.ndarray:
    """G: irradiance (0..255 scale) → 8-bit pixel value."""
    x = np.clip(irradiance, 0, 255) / 255.0
    return np.clip(np.rint(255.0 * x ** (1.0 / GAMMA)), 0, 255).astype(np.uint8)


def inverse_response() -> np.ndarray:
    """G^-1 for pixel values 0..255 (strictly increasing), as pcalib.txt holds it."""
    return 255.0 * (np.arange(256) / 255.0) ** GAMMA


def generate(
    out: str | Path, frames: int = 300, seed: int = 0, size: tuple[int, int] = (640, 480), scene_kind: str = "indoor"
) -> Path:
    """Write a TUM-Mono sequence folder at `out` (written to a temporary folder, then renamed)."""
    out = Path(out)
    tmp = out.with_name(out.name + ".tmp-synth")
    if tmp.exists():
        import shutil

        shutil.rmtree(tmp)
    tmp.mkdir(parents=True)
    rng = np.random.default_rng(seed)
    scene = make_scene(scene_kind, rng)
    texture = make_texture(rng)
    cam = default_camera(*size)
    renderer = Renderer(scene, texture, fov_rays(cam), (cam.height, cam.width))
    rots, positions = camera_path(scene, frames)
    vignette = vignette_image(cam)
    t = 1.0 + np.arange(frames) / FPS
    exposure = 8.0 * (1.0 + 0.25 * np.sin(2 * np.pi * np.arange(frames) / 97.0))
    with zipfile.ZipFile(tmp / "images.zip", "w", zipfile.ZIP_STORED) as zf:
        for i in range(frames):
            irr = renderer.render(rots[i], positions[i]) * vignette * np.float32(exposure[i] / 8.0)
            ok, jpg = cv2.imencode(".jpg", response(irr), [cv2.IMWRITE_JPEG_QUALITY, 95])
            entry = zipfile.ZipInfo(f"{i:05d}.jpg", date_time=(1980, 1, 1, 0, 0, 0))  # deterministic bytes
            zf.writestr(entry, jpg.tobytes())
    with open(tmp / "times.txt", "w") as f:
        for i in range(frames):
            f.write(f"{i:05d} {t[i]:.6f} {exposure[i]:.6f}\n")
    out_size = (640, 480) if size[0] >= 640 and size[1] >= 480 else size  # TUM-Mono's output size
    write_camera_txt(tmp / "camera.txt", cam, "crop", out_size)
    (tmp / "pcalib.txt").write_text(" ".join(f"{v:.9g}" for v in inverse_response()) + "\n")
    cv2.imwrite(str(tmp / "vignette.png"), np.rint(vignette / vignette.max() * 65535).astype(np.uint16))
    quats = Rotation.from_matrix(rots).as_quat()
    gt = np.column_stack([t, positions, quats])
    buf = io.StringIO()
    np.savetxt(buf, gt, fmt="%.9f")
    (tmp / "groundtruth_full.txt").write_text(buf.getvalue())
    n_seg = max(int(math.floor(GT_FRACTION * frames)), 3)
    gt_sync = gt.copy()
    gt_sync[n_seg : frames - n_seg, 1:] = np.nan
    buf = io.StringIO()
    np.savetxt(buf, gt_sync, fmt="%.9f")
    (tmp / "groundtruthSync.txt").write_text(buf.getvalue().replace("nan", "NaN"))
    if out.exists():
        import shutil

        shutil.rmtree(out)
    tmp.rename(out)
    return out
