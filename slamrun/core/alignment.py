"""Sim(3) least-squares alignment of point sets (Horn / Umeyama). Pure functions."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class Sim3:
    """x -> scale * rotation @ x + translation."""

    rotation: np.ndarray
    translation: np.ndarray
    scale: float

    def apply(self, points: np.ndarray) -> np.ndarray:
        return self.scale * points @ self.rotation.T + self.translation

    def matrix(self) -> np.ndarray:
        m = np.eye(4)
        m[:3, :3] = self.scale * self.rotation
        m[:3, 3] = self.translation
        return m


def align_sim3(source: np.ndarray, target: np.ndarray) -> Sim3:
    """The Sim(3) minimising sum ||target_i - (s R source_i + t)||^2.

    Rotation by SVD of the cross-covariance with the reflection fixed, then
    s = sum(a_i . b_i) / sum(a_i . a_i) over the rotated, centred source a_i and centred target b_i,
    then t. Needs at least two distinct points.
    """
    mu_s = source.mean(axis=0)
    mu_t = target.mean(axis=0)
    a = source - mu_s
    b = target - mu_t
    cov = b.T @ a  # sum b_i a_i^T
    u, _, vt = np.linalg.svd(cov)
    d = np.eye(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        d[2, 2] = -1.0
    rot = u @ d @ vt
    ra = a @ rot.T
    denom = float(np.einsum("ij,ij->", ra, ra))
    scale = float(np.einsum("ij,ij->", ra, b)) / denom if denom > 0 else float("nan")
    trans = mu_t - scale * rot @ mu_s
    return Sim3(rot, trans, scale)


def rmse(a: np.ndarray, b: np.ndarray) -> float:
    """Root mean square of the point-to-point distances."""
    return float(np.sqrt(np.mean(np.einsum("ij,ij->i", a - b, a - b))))


def rotation_angle_deg(rot: np.ndarray) -> float:
    """The angle of a rotation matrix, in degrees (robust near 0 and 180)."""
    (r11, r12, r13), (r21, r22, r23), (r31, r32, r33) = np.asarray(rot, float).tolist()
    cos = (r11 + r22 + r33 - 1.0) / 2.0
    sin = math.hypot(r32 - r23, r13 - r31, r21 - r12) / 2.0
    return math.degrees(math.atan2(sin, cos))
