"""Synthetic sequences in a dataset's layout, with known camera-to-world poses.

The scene is a textured room (or courtyard) with boxes in the middle; the camera circles them once,
looking at them, so the path closes a loop and start and end see the same place. The loop follows the seed too
(`PathShape`: size, aspect, turning sense, where it starts, height, speed profile, gaze): two sequences are two
motions, each within the plain loop's envelope (its fastest speed and rotation rate, and the parallax of its first
frames, each within MOTION_SLACK: datasets/envelope.py measures them), so what tracks the plain loop's motion tracks
them. `motion` asks for another envelope on purpose (MOTIONS: the plain loop itself, or harder loops). Frames
are ray-cast through each layout's camera; each layout's module writes them with its files and quirks (its `synth`:
TUM-Mono's vignette, response curve and exposures, EuRoC's nanosecond names and body frame, ...).
Deterministic for a seed.
"""

from __future__ import annotations

import io
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from slamrun.core.camera import FovCamera, PinholeCamera

GAMMA = 1.25  # response G(x) = 255 (x/255)^(1/GAMMA); pcalib holds G^-1
FPS = 30.0
GT_FRACTION = 0.2  # first and last 20 % of the frames carry ground truth


PATH_STREAM = 0x9A7  # the path's random stream: a seed's boxes and texture stay what they were before paths varied
SCALES = {"indoor": 1.0, "outdoor": 5.0}
MOTION_SLACK = 1.1  # a seed's loop moves and turns at most 10 % faster than the plain loop at its fastest, and its
# first frames give at least the plain loop's start parallax / MOTION_SLACK
START_LOOPS = (1 / 30, 2 / 30)  # the start's parallax is over these parts of the loop (10 and 20 of 300 frames)
MOTIONS = {  # motion -> what the paths are
    "default": "the seed's loop, within the plain loop's envelope (MOTION_SLACK)",
    "plain": "the plain loop every sequence had before paths followed their seed, for every seed",
    "hard": "the seed's loop not drawn back, with a stronger speed profile (surge up to 0.5) and twice the gaze "
    "wander: up to about 1.45x the plain loop's fastest speed, 1.85x its rotation rate, 0.6x its start parallax",
}


@dataclass(frozen=True)
class PathShape:
    """The camera's loop around the boxes, in metres and radians; `PathShape.plain(scale)` is the loop every
    sequence had before paths followed their seed."""

    radii: tuple[float, float]  # semi-axes along x and y
    height: float  # the camera's mean height
    bob: tuple[int, float]  # vertical wobble: cycles per loop, amplitude
    turn: int  # +1 anticlockwise seen from above, -1 clockwise
    start: float  # where on the loop the first frame is
    surge: float  # speed profile: the phase advances as 2 pi u + surge sin(2 pi u), |surge| < 1
    gaze: tuple[float, float, float]  # phase offsets of the look-at point's wander (x, y, z)
    scale: float = 1.0  # the scene's (1 indoor, 5 outdoor)
    wander: float = 0.3  # the look-at point's wander (m, the same at either scale, as it always was)

    @classmethod
    def plain(cls, scale: float = 1.0) -> PathShape:
        return cls((2.3 * scale, 1.9 * scale), 1.3 * scale, (3, 0.1 * scale), 1, 0.0, 0.0, (0.0, 0.0, 0.0), scale)


def path_shape(kind: str, seed: int, motion: str = "default") -> PathShape:
    """The loop of a sequence of seed `seed`: size (0.92-1.1 of the plain loop's), aspect (either axis the long one,
    up to the plain loop's 1.21), turning sense, start, height, vertical wobble, speed profile and gaze drawn from
    the seed, then drawn back towards the plain loop until its fastest translation and rotation per step are within
    MOTION_SLACK of the plain loop's (`path_motion`) and its start's parallax at least the plain loop's over
    MOTION_SLACK (`start_parallax`): the boxes are never nearer, the motion about as fast, the start no slower.
    `motion` (MOTIONS): "plain" the plain loop whatever the seed, "hard" the drawn loop with a stronger speed
    profile and gaze wander, not drawn back."""
    if motion not in MOTIONS:
        raise ValueError(f"motion {motion!r}: one of {', '.join(MOTIONS)}")
    scale = SCALES[kind]
    plain = PathShape.plain(scale)
    if motion == "plain":
        return plain
    rng = np.random.default_rng([seed, PATH_STREAM])
    size = rng.uniform(0.92, 1.1)
    aspect = rng.uniform(1.0, 2.3 / 1.9)
    long_side = 2.3 * size * scale
    radii = (long_side, long_side / aspect) if rng.random() < 0.5 else (long_side / aspect, long_side)
    radii = (max(radii[0], 1.9 * scale), max(radii[1], 1.9 * scale))  # never nearer the boxes than the plain loop
    cycles = int(rng.integers(2, 5))
    drawn = PathShape(
        radii=radii,
        height=scale * rng.uniform(1.15, 1.45),
        bob=(cycles, scale * rng.uniform(0.5, 1.0) * 0.3 / cycles),
        turn=1 if rng.random() < 0.5 else -1,
        start=rng.uniform(0, 2 * np.pi),
        surge=rng.uniform(-0.2, 0.2),
        gaze=tuple(rng.uniform(-np.pi, np.pi, 3)),
        scale=scale,
    )
    if motion == "hard":
        return replace(drawn, surge=2.5 * drawn.surge, wander=2 * plain.wander)
    limit = path_motion(plain)
    start_limit = [start_parallax(plain, part) / MOTION_SLACK for part in START_LOOPS]
    for weight in np.linspace(1.0, 0.0, 11):
        shape = _toward(plain, drawn, weight)
        speed, turning = path_motion(shape)
        if (
            speed <= limit[0] * MOTION_SLACK
            and turning <= limit[1] * MOTION_SLACK
            and all(start_parallax(shape, part) >= low for part, low in zip(START_LOOPS, start_limit, strict=True))
        ):
            return shape
    return plain


def start_parallax(shape: PathShape, part: float) -> float:
    """The translation over the first `part` of the loop, the shorter of the two ways round (a backward run starts at
    the end), over the distance from the start to the boxes' middle: the parallax a monocular initialisation starts
    from (radians, small-angle)."""
    _, pos = loop_poses(shape, np.array([0.0, part, 1.0 - part]))
    depth = np.linalg.norm(pos[0] - np.array([0.0, 0.0, 0.7]) * shape.scale)
    return float(min(np.linalg.norm(pos[1] - pos[0]), np.linalg.norm(pos[2] - pos[0])) / depth)


def _toward(plain: PathShape, drawn: PathShape, w: float) -> PathShape:
    """`drawn`'s sense, start and wobble cycles, its sizes and rates `w` of the way from the plain loop's."""

    def mix(a, b):
        return (1 - w) * a + w * b

    return PathShape(
        radii=(mix(plain.radii[0], drawn.radii[0]), mix(plain.radii[1], drawn.radii[1])),
        height=mix(plain.height, drawn.height),
        bob=(drawn.bob[0], mix(plain.bob[1] * plain.bob[0], drawn.bob[1] * drawn.bob[0]) / drawn.bob[0]),
        turn=drawn.turn,
        start=drawn.start,
        surge=mix(plain.surge, drawn.surge),
        gaze=tuple(mix(p, d) for p, d in zip(plain.gaze, drawn.gaze, strict=True)),
        scale=drawn.scale,
        wander=mix(plain.wander, drawn.wander),
    )


def path_motion(shape: PathShape, samples: int = 3600) -> tuple[float, float]:
    """The loop's fastest translation (m) and rotation (rad) between two of `samples` equally spaced frames."""
    rots, pos = loop_poses(shape, np.arange(samples + 1) / samples)
    step = np.linalg.norm(np.diff(pos, axis=0), axis=1)
    rel = np.einsum("nji,njk->nik", rots[:-1], rots[1:])
    angle = np.arccos(np.clip((np.trace(rel, axis1=1, axis2=2) - 1) / 2, -1.0, 1.0))
    return float(step.max()), float(angle.max())


@dataclass(frozen=True)
class Scene:
    room_lo: np.ndarray
    room_hi: np.ndarray
    boxes: tuple[tuple[np.ndarray, np.ndarray], ...]
    texels_per_m: float
    path: PathShape
    look_at: np.ndarray


def make_scene(kind: str, rng: np.random.Generator, path: PathShape | None = None) -> Scene:
    """The room (or courtyard) and its boxes from `rng`; the camera's loop is `path` (the plain loop if None)."""
    scale = SCALES[kind]
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
        path=path or PathShape.plain(scale),
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


def camera_path(scene: Scene, n: int, laps: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Camera-to-world rotations (n, 3, 3) and positions (n, 3): `laps` smooth loops around the boxes."""
    return camera_path_at(scene, laps * np.arange(n) / max(n - 1, 1))


def lap_length(scene: Scene, samples: int = 2000) -> float:
    """The length of one loop of the scene's path (m)."""
    _, pos = camera_path_at(scene, np.linspace(0, 1, samples + 1))
    return float(np.linalg.norm(np.diff(pos, axis=0), axis=1).sum())


def camera_path_at(scene: Scene, loops: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The scene's camera-to-world rotations and positions `loops` loops after the first frame (1: one loop on)."""
    return loop_poses(scene.path, loops, scene.look_at)


def loop_poses(shape: PathShape, loops: np.ndarray, look_at: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Rotations and positions of `shape`'s loop, looking at the boxes' middle (`look_at`), `loops` loops on."""
    loops = np.asarray(loops, float)
    if look_at is None:
        look_at = np.array([0.0, 0.0, 0.7]) * shape.scale
    u = 2 * np.pi * loops
    phase = shape.start + shape.turn * (u + shape.surge * np.sin(u))
    a, b = shape.radii
    cycles, amplitude = shape.bob
    pos = np.column_stack([a * np.cos(phase), b * np.sin(phase), shape.height + amplitude * np.sin(cycles * u)])
    gx, gy, gz = shape.gaze
    wander = shape.wander * np.column_stack([np.sin(2 * u + gx), np.cos(u + gy), 2 / 3 * np.sin(u + gz)])
    fwd = look_at + wander - pos
    fwd /= np.linalg.norm(fwd, axis=1, keepdims=True)
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right, axis=1, keepdims=True)
    down = np.cross(fwd, right)
    rot = np.stack([right, down, fwd], axis=2)  # columns: camera x, y, z in world
    roll = Rotation.from_rotvec(np.outer(0.05 * np.sin(2 * u), [0, 0, 1])).as_matrix()
    return rot @ roll, pos


class Renderer:
    """Ray-casts the scene for a fixed set of camera rays (one per pixel).

    The image is cut into blocks of BLOCK x BLOCK pixels, grouped into tiles of about 20,000 pixels (small
    enough for a tile's arrays to stay in the CPU cache). Each block has the cone bounding its rays; a box
    is ray-cast only on the rectangle of a tile covered by blocks whose cone meets the box's bounding
    sphere, which is conservative (no pixel of the box is ever skipped).
    """

    BLOCK = 16
    TILE_BLOCKS = 9

    def __init__(self, scene: Scene, texture: np.ndarray, rays_cam: np.ndarray, shape: tuple[int, int]):
        self.scene = scene
        self.texture = np.clip(np.rint(texture), 0, 255).astype(np.uint8)
        self.shape = shape
        rng = np.random.default_rng(99)
        n_faces = 6 * (1 + len(scene.boxes))
        if n_faces > 256:
            raise ValueError(f"{len(scene.boxes)} boxes: at most 41 (face ids are 8-bit)")
        offsets = rng.uniform(0, texture.shape[0], size=(n_faces, 2)).astype(np.float32)
        shade = rng.uniform(0.75, 1.0, size=n_faces).astype(np.float32)

        def lut(values: np.ndarray, dtype) -> np.ndarray:  # a 256-entry table for cv2.LUT
            table = np.zeros(256, dtype)
            table[: len(values)] = values
            return table

        self._face_offset_x, self._face_offset_y = lut(offsets[:, 0], np.float32), lut(offsets[:, 1], np.float32)
        self._face_shade = lut(shade, np.float32)
        self._face_axis = lut((np.arange(n_faces) % 6) // 2, np.uint8)
        self.box_corners = np.array(
            [[[(lo, hi)[(c >> k) & 1][k] for k in range(3)] for c in range(8)] for lo, hi in scene.boxes]
        ).reshape(-1, 8, 3)
        rays = rays_cam.reshape(*shape, 3).astype(np.float32)
        self.block_bounds = _block_bounds(rays, self.BLOCK)
        side = self.BLOCK * self.TILE_BLOCKS
        self.tiles = [
            (slice(r, min(r + side, shape[0])), slice(c, min(c + side, shape[1])))
            for r in range(0, shape[0], side)
            for c in range(0, shape[1], side)
        ]
        self._tile_rays = [np.ascontiguousarray(rays[rows, cols].transpose(2, 0, 1)) for rows, cols in self.tiles]
        self._room_lo = scene.room_lo.astype(np.float32).reshape(3, 1, 1)
        self._room_hi = scene.room_hi.astype(np.float32).reshape(3, 1, 1)
        self._box_lo = [lo.astype(np.float32).reshape(3, 1, 1) for lo, _ in scene.boxes]
        self._box_hi = [hi.astype(np.float32).reshape(3, 1, 1) for _, hi in scene.boxes]
        self._map_x = np.empty(shape, np.float32)
        self._map_y = np.empty(shape, np.float32)
        self._face = np.empty(shape, np.uint8)

    def render(self, rot: np.ndarray, pos: np.ndarray) -> np.ndarray:
        """Irradiance-like image in 0..255 (float32) seen from camera-to-world (rot, pos)."""
        rot32, o = rot.astype(np.float32), pos.astype(np.float32).reshape(3, 1, 1)
        visible = self._visible_blocks(rot, pos)
        for (rows, cols), rays in zip(self.tiles, self._tile_rays, strict=True):
            self._render_tile(rows, cols, rays, rot32, o, visible)
        img = cv2.remap(self.texture, self._map_x, self._map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
        return cv2.multiply(img, cv2.LUT(self._face, self._face_shade), dtype=cv2.CV_32F)

    def _visible_blocks(self, rot: np.ndarray, pos: np.ndarray) -> np.ndarray:
        """(block rows, block cols, boxes): whether any ray of a block can meet a box.

        For a box wholly in front of the camera (z > 0 at its corners) its image in normalised pinhole
        coordinates (x/z, y/z) is the convex hull of its corners' images, so the corners' bounding
        rectangle bounds it exactly and is compared with each block's rectangle. A box reaching behind
        the camera, or rays that are not all in front, fall back to every block.
        """
        n_boxes = len(self.scene.boxes)
        if self.block_bounds is None or not n_boxes:
            grid = (-(-self.shape[0] // self.BLOCK), -(-self.shape[1] // self.BLOCK))
            return np.ones((*grid, n_boxes), bool)
        corners = (self.box_corners - pos) @ rot  # (boxes, 8, 3) camera frame
        z = corners[..., 2]
        in_front = (z > 1e-6).all(axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            x, y = corners[..., 0] / z, corners[..., 1] / z
        lo_x, hi_x, lo_y, hi_y = x.min(axis=1), x.max(axis=1), y.min(axis=1), y.max(axis=1)
        b = self.block_bounds  # (by, bx, 4): min x/z, max x/z, min y/z, max y/z of the block's rays
        overlap = (b[..., 1:2] >= lo_x) & (b[..., 0:1] <= hi_x) & (b[..., 3:4] >= lo_y) & (b[..., 2:3] <= hi_y)
        return overlap | ~in_front

    def _render_tile(self, rows: slice, cols: slice, rays: np.ndarray, rot: np.ndarray, o: np.ndarray, visible) -> None:
        """Fill the tile's texture maps and face ids. Arrays are (3, h, w): one plane per world axis."""
        w = (rot @ rays.reshape(3, -1)).reshape(rays.shape)  # world ray directions
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            inv = np.float32(1.0) / w
            # Room, seen from inside: along each axis the ray leaves through the farther of its two walls
            # (a ray parallel to a wall gets +inf there); the nearest of the three exits is the wall seen.
            exits = np.maximum((self._room_lo - o) * inv, (self._room_hi - o) * inv)
            t = np.minimum(np.minimum(exits[0], exits[1]), exits[2])
            ahead = (w > 0).view(np.uint8)  # per axis: 1 when the ray runs towards the upper wall
            face = np.where(exits[0] == t, ahead[0], np.where(exits[1] == t, 2 + ahead[1], 4 + ahead[2]))
            b = self.BLOCK
            tile_vis = visible[rows.start // b : -(-rows.stop // b), cols.start // b : -(-cols.stop // b)]
            for i in np.flatnonzero(tile_vis.any(axis=(0, 1))):
                # The tile's rectangle covered by blocks that may see box i.
                by = np.flatnonzero(tile_vis[:, :, i].any(axis=1))
                bx = np.flatnonzero(tile_vis[:, :, i].any(axis=0))
                sub = (slice(by[0] * b, (by[-1] + 1) * b), slice(bx[0] * b, (bx[-1] + 1) * b))
                self._cast_box(int(i), o, w[:, sub[0], sub[1]], inv[:, sub[0], sub[1]], t[sub], face[sub])
        # Texture coordinates: the hit point's two coordinates in the face's plane, in texels, plus the
        # face's offset into the texture. Faces are uint8 so that look-ups are cv2.LUT calls.
        axis = cv2.LUT(face, self._face_axis)
        u, y, v = o + w * t
        np.copyto(u, y, where=axis == 0)  # x walls: (y, z); y walls: (x, z); z walls: (x, y)
        np.copyto(v, y, where=axis == 2)
        tpm = np.float32(self.scene.texels_per_m)
        self._map_x[rows, cols] = u * tpm + cv2.LUT(face, self._face_offset_x)
        self._map_y[rows, cols] = v * tpm + cv2.LUT(face, self._face_offset_y)
        self._face[rows, cols] = face

    def _cast_box(self, i: int, o: np.ndarray, w: np.ndarray, inv: np.ndarray, t: np.ndarray, face: np.ndarray) -> None:
        """Slab test of box i; where it is nearer, write its distance and face into `t` and `face` (views)."""
        lo_side, hi_side = (self._box_lo[i] - o) * inv, (self._box_hi[i] - o) * inv
        near = np.minimum(lo_side, hi_side)
        far = np.maximum(lo_side, hi_side)
        tmin = np.maximum(np.maximum(near[0], near[1]), near[2])
        tfar = np.minimum(np.minimum(far[0], far[1]), far[2])
        hit = (tmin > 0) & (tmin <= tfar) & (tmin < t)
        if not hit.any():
            return
        # The face entered: the axis whose slab is entered last, on the side the ray comes from.
        back = (w < 0).view(np.uint8)  # per axis: 1 when the ray enters through the upper side
        entered = np.where(near[0] == tmin, back[0], np.where(near[1] == tmin, 2 + back[1], 4 + back[2]))
        np.copyto(t, tmin, where=hit)
        np.copyto(face, entered + 6 * (i + 1), where=hit)


def _block_bounds(rays: np.ndarray, block: int) -> np.ndarray | None:
    """For (h, w, 3) camera rays: each block's rectangle in normalised pinhole coordinates (x/z, y/z), as
    (block rows, block cols, 4) = min x, max x, min y, max y; None when some ray does not point forward."""
    if not (rays[..., 2] > 0).all():
        return None
    x, y = rays[..., 0] / rays[..., 2], rays[..., 1] / rays[..., 2]
    h, w = rays.shape[:2]
    by, bx = -(-h // block), -(-w // block)
    bounds = np.zeros((by, bx, 4))
    for r in range(by):
        for c in range(bx):
            sub = (slice(r * block, (r + 1) * block), slice(c * block, (c + 1) * block))
            bounds[r, c] = x[sub].min(), x[sub].max(), y[sub].min(), y[sub].max()
    return bounds


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


@dataclass(frozen=True)
class Synth:
    """What every layout's writer renders from: the scene, its texture and the camera's loop."""

    frames: int
    seed: int
    size: tuple[int, int]
    scene_kind: str
    name: str
    laps: int = 1  # loops over the sequence (KITTI's drive: long enough for its 100 m segments)
    motion: str = "default"  # the paths' envelope (MOTIONS)

    @property
    def path(self) -> PathShape:
        return path_shape(self.scene_kind, self.seed, self.motion)

    @property
    def scene(self) -> Scene:
        return make_scene(self.scene_kind, np.random.default_rng(self.seed), self.path)

    def renderer(self, cam) -> tuple[Scene, Renderer]:
        rng = np.random.default_rng(self.seed)
        scene = make_scene(self.scene_kind, rng, self.path)
        return scene, Renderer(scene, make_texture(rng), camera_rays(cam), (cam.height, cam.width))

    def poses_at(self, scene: Scene, fraction: np.ndarray) -> np.ndarray:
        """Camera-to-world 4x4 poses at `fraction` of the sequence's path (0: first frame, 1: last)."""
        rots, positions = camera_path_at(scene, self.laps * np.asarray(fraction, float))
        t = np.tile(np.eye(4), (len(rots), 1, 1))
        t[:, :3, :3], t[:, :3, 3] = rots, positions
        return t

    def images(self, cam, exposure: np.ndarray | None = None, vignette: np.ndarray | None = None):
        """(index, 8-bit frame) for every frame: rendered, then through the response curve when `exposure` is
        given (TUM-Mono's photometric model), else linear."""
        scene, renderer = self.renderer(cam)
        rots, positions = camera_path(scene, self.frames, self.laps)
        for i in range(self.frames):
            irr = renderer.render(rots[i], positions[i])
            if exposure is None:
                yield i, np.clip(np.rint(irr), 0, 255).astype(np.uint8)
            else:
                yield i, response(irr * vignette * np.float32(exposure[i] / 8.0))


def loop_fraction(times: np.ndarray, frame_times: np.ndarray) -> np.ndarray:
    """Where on the loop (0: first frame, 1: last) the camera is at `times`, frame i being at i / (n - 1): piecewise
    linear between the frames' own (irregular) times, extended linearly beyond them."""
    n = len(frame_times)
    k = np.clip(np.searchsorted(frame_times, times) - 1, 0, n - 2)
    step = (times - frame_times[k]) / (frame_times[k + 1] - frame_times[k])
    return (k + step) / (n - 1)


def camera_rays(cam) -> np.ndarray:
    """One ray (x, y, 1) per pixel of any camera model, row by row."""
    u, v = np.meshgrid(np.arange(cam.width, dtype=float), np.arange(cam.height, dtype=float))
    xy = cam.unproject(np.column_stack([u.ravel(), v.ravel()]))
    return np.column_stack([xy, np.ones(len(xy))])


def tum_rows(t: np.ndarray, poses: np.ndarray) -> np.ndarray:
    quats = Rotation.from_matrix(poses[:, :3, :3]).as_quat()
    return np.column_stack([t, poses[:, :3, 3], quats])


def savetxt(path: Path, rows: np.ndarray, fmt: str = "%.9f", header: str = "") -> None:
    buf = io.StringIO()
    np.savetxt(buf, rows, fmt=fmt, header=header, comments="")
    path.write_text(buf.getvalue().replace("nan", "NaN"))
