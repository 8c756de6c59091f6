"""python -m slamrun.methods.reference_vo --images DIR --times FILE --camera FILE --out FILE

Exit codes: 0 a trajectory was written (possibly cut short by LOST), 2 never initialised, 1 bad input.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import cv2
import numpy as np

from .vo import Settings, VisualOdometry, rotation_to_quaternion  # its own folder's, whatever the folder is named


def read_pinhole_camera(path: Path) -> tuple[np.ndarray, int, int]:
    """A pinhole camera.txt (`fx fy cx cy 0` relative to the size, then `width height`)."""
    lines = [ln.split() for ln in path.read_text().splitlines() if ln.strip()]
    vals = [float(v) for v in (lines[0][1:] if lines[0][0].isalpha() else lines[0])]
    w, h = int(lines[1][0]), int(lines[1][1])
    fx, fy, cx, cy = vals[:4]
    if len(vals) > 4 and abs(vals[4]) > 0:
        raise ValueError(f"{path}: distortion {vals[4]} given; the reference VO needs a rectified pinhole view")
    if cx < 1 and cy < 1:
        fx, fy, cx, cy = fx * w, fy * h, cx * w - 0.5, cy * h - 0.5
    return np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]]), w, h


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="reference_vo", description=__doc__)
    p.add_argument("--images", type=Path, required=True, help="folder of frames (sorted names = order)")
    p.add_argument("--times", type=Path, required=True, help="times.txt: 'id timestamp [exposure]' per frame")
    p.add_argument("--camera", type=Path, required=True, help="pinhole camera.txt")
    p.add_argument("--out", type=Path, required=True, help="TUM trajectory to write")
    p.add_argument("--max-corners", type=int, default=Settings.max_corners)
    p.add_argument("--seed", type=int, default=0, help="seed of OpenCV's RANSAC")
    a = p.parse_args(argv)

    try:
        K, w, h = read_pinhole_camera(a.camera)
        times = np.loadtxt(a.times, ndmin=2)[:, 1]
    except (OSError, ValueError, IndexError) as exc:
        print(f"reference_vo: bad input: {exc}", file=sys.stderr)
        return 1
    frames = sorted(f for f in a.images.iterdir() if f.suffix.lower() in (".png", ".jpg", ".jpeg", ".pgm", ".ppm"))
    if len(frames) != len(times):
        print(f"reference_vo: {len(frames)} images but {len(times)} timestamps in {a.times}", file=sys.stderr)
        return 1
    cv2.setRNGSeed(a.seed)
    cv2.setNumThreads(1)
    vo = VisualOdometry(K, Settings(max_corners=a.max_corners))
    t0 = time.perf_counter()
    decode_s = 0.0
    for i, f in enumerate(frames):
        td = time.perf_counter()
        img = cv2.imread(str(f), cv2.IMREAD_GRAYSCALE)
        decode_s += time.perf_counter() - td
        if img is None or img.shape != (h, w):
            print(f"reference_vo: {f} unreadable or not {w}x{h}", file=sys.stderr)
            return 1
        vo.process(i, img)
        if vo.lost:
            break
    elapsed = time.perf_counter() - t0
    if not vo.initialised:
        print(f"NOT INITIALIZED after {len(frames)} frames: no pair of frames gave enough parallax and inliers")
        a.out.write_text("")
        return 2
    traj = vo.trajectory()
    with open(a.out, "w") as out:
        for frame, R_wc, c in traj:
            q = rotation_to_quaternion(R_wc)
            out.write(
                f"{times[frame]:.6f} {c[0]:.9f} {c[1]:.9f} {c[2]:.9f} {q[0]:.9f} {q[1]:.9f} {q[2]:.9f} {q[3]:.9f}\n"
            )
    n = i + 1
    print(f"tracked {len(traj)} of {len(frames)} frames, {len(vo.keyframes)} keyframes, {n / elapsed:.1f} fps")
    return 0


if __name__ == "__main__":
    sys.exit(main())
