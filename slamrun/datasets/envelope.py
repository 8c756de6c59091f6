"""The motion envelope of a camera path: how fast it moves and turns per frame, and how much parallax its first
frames give, for synthetic paths and real ground truth alike (pure functions of poses and times).

Figures per frame at the camera's frame rate: a ground truth sampled faster than the camera (EuRoC 200 Hz, TUM RGB-D
100 Hz) is first taken at the frames (`at_frame_rate`, the pose nearest each frame's time). The start figures are
those of the harder of the two directions a run may take (forward from the first frame, backward from the last):
the translation over the first k frames relative to the scene's depth (the parallax a monocular initialisation
has to work with; the depth is the distance to what the camera looks at) and the rotation over them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

STARTS = (10, 20)  # the start figures are over the first 10 and 20 frames


@dataclass(frozen=True)
class Envelope:
    """A path's motion per frame at `fps` (speed in m, rotation in degrees); the start figures by number of
    frames, the harder direction's (least parallax, most rotation)."""

    fps: float
    frames: int
    speed_median: float
    speed_p95: float
    speed_max: float
    rotation_median: float
    rotation_p95: float
    rotation_max: float
    depth: float | None  # what the start parallax is relative to (None: not known, no parallax figure)
    start_translation: dict[int, float]  # m over the first k frames, the shorter of the two directions'
    start_rotation: dict[int, float]  # degrees over the first k frames, the larger of the two directions'

    @property
    def speed_max_s(self) -> float:
        return self.speed_max * self.fps

    @property
    def speed_median_s(self) -> float:
        return self.speed_median * self.fps

    @property
    def rotation_max_s(self) -> float:
        return self.rotation_max * self.fps

    def start_parallax(self, k: int) -> float | None:
        """Translation over the first `k` frames over the scene's depth (radians, small-angle), or None."""
        return None if self.depth is None else self.start_translation[k] / self.depth

    def row(self) -> dict[str, float | None]:
        """The figures as one flat row (a table's)."""
        row = {
            "fps": self.fps,
            "frames": self.frames,
            "speed m/frame median": self.speed_median,
            "speed m/frame max": self.speed_max,
            "speed m/s median": self.speed_median_s,
            "speed m/s max": self.speed_max_s,
            "rotation deg/frame median": self.rotation_median,
            "rotation deg/frame max": self.rotation_max,
            "rotation deg/s max": self.rotation_max_s,
            "depth m": self.depth,
        }
        for k in sorted(self.start_translation):
            row[f"start {k} m"] = self.start_translation[k]
            row[f"start {k} parallax"] = self.start_parallax(k)
            row[f"start {k} deg"] = self.start_rotation[k]
        return row


def rotation_angles(rotations: np.ndarray, others: np.ndarray) -> np.ndarray:
    """Angles (degrees) of the relative rotations between `rotations` and `others` (each (n, 3, 3))."""
    rel = np.einsum("nji,njk->nik", rotations, others)
    cos = (np.trace(rel, axis1=1, axis2=2) - 1) / 2
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))  # NaN stays NaN


def at_frame_rate(
    times: np.ndarray, positions: np.ndarray, rotations: np.ndarray, fps: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The poses nearest in time to frames at `fps` over the span of `times` (increasing): (times, positions,
    rotations) of those frames, NaN where no pose lies within half a frame of the frame's time (a gap in a motion
    capture). For a ground truth sampled at the frame rate or faster."""
    times = np.asarray(times, float)
    frame_times = times[0] + np.arange(int(np.floor((times[-1] - times[0]) * fps)) + 1) / fps
    k = np.clip(np.searchsorted(times, frame_times), 1, len(times) - 1)
    nearest = np.where(frame_times - times[k - 1] <= times[k] - frame_times, k - 1, k)
    gap = np.abs(times[nearest] - frame_times) > 0.5 / fps
    positions, rotations = positions[nearest].astype(float), rotations[nearest].astype(float)
    positions[gap], rotations[gap] = np.nan, np.nan
    return frame_times, positions, rotations


def motion_envelope(
    times: np.ndarray,
    positions: np.ndarray,
    rotations: np.ndarray,
    depth: float | None = None,
    fps: float | None = None,
    starts: tuple[int, ...] = STARTS,
) -> Envelope:
    """The envelope of camera-to-world poses (`positions` (n, 3), `rotations` (n, 3, 3)) at `times` (seconds,
    increasing). `fps`: the camera's frame rate, the poses taken at it first; None: the poses are the frames.
    `depth`: the scene's depth at the start (m), for the start parallax."""
    times, positions, rotations = np.asarray(times, float), np.asarray(positions, float), np.asarray(rotations, float)
    if fps is not None:
        times, positions, rotations = at_frame_rate(times, positions, rotations, fps)
    else:
        fps = 1.0 / float(np.median(np.diff(times)))
    n = len(times)
    if n < 2:
        raise ValueError("a motion envelope needs at least two poses")
    step = np.linalg.norm(np.diff(positions, axis=0), axis=1)
    turn = rotation_angles(rotations[:-1], rotations[1:])
    step, turn = step[np.isfinite(step)], turn[np.isfinite(turn)]  # steps across a gap of the ground truth left out
    moved: dict[int, float] = {}
    turned: dict[int, float] = {}
    for k in starts:
        k_ = min(k, n - 1)
        fw = np.linalg.norm(positions[k_] - positions[0]), rotation_angles(rotations[:1], rotations[k_ : k_ + 1])[0]
        bw = (
            np.linalg.norm(positions[-1 - k_] - positions[-1]),
            rotation_angles(rotations[-1:], rotations[-1 - k_ :][:1])[0],
        )
        moved[k], turned[k] = float(min(fw[0], bw[0])), float(max(fw[1], bw[1]))
    return Envelope(
        fps=float(fps),
        frames=n,
        speed_median=float(np.median(step)),
        speed_p95=float(np.percentile(step, 95)),
        speed_max=float(step.max()),
        rotation_median=float(np.median(turn)),
        rotation_p95=float(np.percentile(turn, 95)),
        rotation_max=float(turn.max()),
        depth=depth,
        start_translation=moved,
        start_rotation=turned,
    )


def synthetic_envelope(
    kind: str = "indoor", seed: int | None = None, frames: int = 300, motion: str = "default"
) -> Envelope:
    """The envelope of a synthetic sequence's path (`slamrun synth`, one loop over `frames` frames at synth.FPS);
    seed None: the plain loop every sequence had before paths followed their seed. Depth: the distance from the
    first frame to the point the camera looks at (the boxes' middle)."""
    from slamrun.datasets.synth import FPS, SCALES, PathShape, loop_poses, path_shape

    shape = PathShape.plain(SCALES[kind]) if seed is None else path_shape(kind, seed, motion)
    rots, pos = loop_poses(shape, np.arange(frames) / max(frames - 1, 1))
    look_at = np.array([0.0, 0.0, 0.7]) * shape.scale
    depth = float(min(np.linalg.norm(pos[0] - look_at), np.linalg.norm(pos[-1] - look_at)))
    return motion_envelope(np.arange(frames) / FPS, pos, rots, depth=depth)
