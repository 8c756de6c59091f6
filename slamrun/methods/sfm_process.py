"""The structure-from-motion family's process (colmap, glomap):
`python -m slamrun.methods.sfm_process --images ... --times ... --camera ... --out ...`.

`--mapper incremental` (colmap) maps with COLMAP's incremental SfM, `--mapper global` (glomap) with GLOMAP's
global SfM (`pycolmap.global_mapping`: rotation averaging, then global positioning, then bundle adjustment),
both from the same features and sequential matches, with the camera's intrinsics fixed.
Exit codes: 0 a trajectory was written, 2 no model was built, 1 bad input.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np


def run(argv: list[str] | None = None) -> int:
    import pycolmap

    a = _parse(argv)

    threads = len(os.sched_getaffinity(0))
    cam = json.loads(a.camera.read_text())
    times = np.loadtxt(a.times, ndmin=2)[:, 1]
    names = sorted(f.name for f in a.images.iterdir() if f.suffix.lower() in (".png", ".jpg"))
    if len(names) != len(times):
        print(f"colmap: {len(names)} images but {len(times)} timestamps", file=sys.stderr)
        return 1
    chosen = names[:: a.stride]
    if names[-1] not in chosen:
        chosen.append(names[-1])
    db = a.workdir / "database.db"
    sparse = a.workdir / "sparse"
    sparse.mkdir(exist_ok=True)

    t0, t1, t2 = _features_and_matches(pycolmap, a, cam, db, chosen, threads)
    if a.mapper == "global":
        models = pycolmap.global_mapping(db, a.images, sparse, options=_global_options(pycolmap, a, threads))
    else:
        models = pycolmap.incremental_mapping(db, a.images, sparse, options=_incremental_options(pycolmap, a, threads))
    t3 = time.perf_counter()
    print(f"extraction {t1 - t0:.1f} s, matching {t2 - t1:.1f} s, mapping {t3 - t2:.1f} s; {len(models)} model(s)")
    if not models:
        print(f"NOT INITIALIZED: {a.mapper} mapping built no model from {len(chosen)} frames")
        a.out.write_text("")
        return 2
    rows = _write_poses(max(models.values(), key=lambda r: r.num_reg_images()), names, times, a.out)
    print(f"registered {len(rows)} of {len(chosen)} frames in the largest of {len(models)} model(s)")
    return 0


def _parse(argv: list[str] | None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog="colmap")
    for name in ("--images", "--times", "--camera", "--out", "--workdir"):
        ap.add_argument(name, type=Path, required=True)
    for name, default in (
        ("--stride", 3),
        ("--max-features", 1024),
        ("--overlap", 5),
        ("--max-image-size", 640),
        ("--global-ba-every", 20),
        ("--seed", 0),
        ("--first-octave", 0),
        ("--ba-iterations", 3),
        ("--min-num-matches", 15),
    ):
        ap.add_argument(name, type=int, default=default)
    ap.add_argument("--mapper", choices=("incremental", "global"), default="incremental")
    return ap.parse_args(argv)


def _features_and_matches(pycolmap, a: argparse.Namespace, cam: dict, db: Path, chosen: list[str], threads: int):
    """SIFT features of the chosen frames and their sequential matches into `db`; the times at each step."""
    reader = pycolmap.ImageReaderOptions()
    reader.camera_model = "PINHOLE"
    # COLMAP puts the centre of the first pixel at (0.5, 0.5); the view's K at (0, 0).
    reader.camera_params = f"{cam['fx']},{cam['fy']},{cam['cx'] + 0.5},{cam['cy'] + 0.5}"
    extraction = pycolmap.FeatureExtractionOptions()
    extraction.num_threads = threads
    extraction.max_image_size = a.max_image_size
    extraction.sift.max_num_features = a.max_features
    extraction.sift.first_octave = a.first_octave
    t0 = time.perf_counter()
    pycolmap.extract_features(
        db,
        a.images,
        image_names=chosen,
        camera_mode=pycolmap.CameraMode.SINGLE,
        reader_options=reader,
        extraction_options=extraction,
        device=pycolmap.Device.cpu,
    )
    t1 = time.perf_counter()
    matching = pycolmap.FeatureMatchingOptions()
    matching.num_threads = threads
    pairing = pycolmap.SequentialPairingOptions()
    pairing.overlap = a.overlap
    pairing.quadratic_overlap = False
    pycolmap.match_sequential(db, matching_options=matching, pairing_options=pairing, device=pycolmap.Device.cpu)
    t2 = time.perf_counter()
    return t0, t1, t2


def _write_poses(rec, names: list[str], times: np.ndarray, out: Path) -> list:
    """The registered frames' poses (camera-to-world) at their original times, as TUM rows, into `out`."""
    index = {n: i for i, n in enumerate(names)}
    rows = []
    for img in rec.images.values():
        if not img.has_pose:
            continue
        world_from_cam = img.cam_from_world().inverse()
        R = world_from_cam.rotation.matrix()
        c = world_from_cam.translation
        q = _quat(R)
        rows.append((times[index[img.name]], *c, *q))
    rows.sort()
    with open(out, "w") as f:
        for r in rows:
            f.write(" ".join(f"{v:.9f}" for v in r) + "\n")
    return rows


def _incremental_options(pycolmap, a: argparse.Namespace, threads: int):
    """COLMAP's incremental mapper: intrinsics fixed, global bundle adjustment every `--global-ba-every` images."""
    opts = pycolmap.IncrementalPipelineOptions()
    opts.num_threads = threads
    opts.random_seed = a.seed
    opts.extract_colors = False
    opts.ba_refine_focal_length = False
    opts.ba_refine_principal_point = False
    opts.ba_refine_extra_params = False
    opts.ba_global_frames_freq = a.global_ba_every
    opts.ba_global_points_freq = 50 * a.global_ba_every
    opts.multiple_models = True
    return opts


def _global_options(pycolmap, a: argparse.Namespace, threads: int):
    """GLOMAP's global mapper on the CPU: intrinsics fixed (the view's pinhole), `--ba-iterations` rounds of
    bundle adjustment and retriangulation, image pairs with at least `--min-num-matches` inliers."""
    opts = pycolmap.GlobalPipelineOptions()
    opts.num_threads = threads
    opts.random_seed = a.seed
    opts.min_num_matches = a.min_num_matches
    opts.multiple_models = True
    mapper = opts.mapper
    mapper.num_threads = threads
    mapper.random_seed = a.seed
    mapper.ba_num_iterations = a.ba_iterations
    mapper.global_positioning.use_gpu = False
    mapper.bundle_adjustment.ceres.use_gpu = False
    mapper.bundle_adjustment.refine_focal_length = False
    mapper.bundle_adjustment.refine_principal_point = False
    mapper.bundle_adjustment.refine_extra_params = False
    return opts


def _quat(R):
    from scipy.spatial.transform import Rotation

    q = Rotation.from_matrix(R).as_quat()
    return q if q[3] >= 0 else -q


if __name__ == "__main__":
    sys.exit(run())
