"""The view cache: prepared views built once per (sequence, direction, profile, perturbation), in a
content-addressed folder (slamrun.datasets.view describes what a view holds; slamrun.datasets.perturb the
perturbations).

Views are built in a temporary folder and renamed, and a file lock makes concurrent requests for the same
view wait for one builder.
"""

from __future__ import annotations

import fcntl
import hashlib
import json
import os
import secrets
import shutil
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import cv2
import numpy as np

from slamrun.core.camera import (
    CameraFile,
    rectification_maps,
    rectification_problem,
    rectified_pinhole,
    scaled_camera_file,
    write_camera_txt,
)
from slamrun.datasets.layouts import open_sequence
from slamrun.datasets.perturb import BASELINE, Perturbation, kept_frames, perturb_frame, scaled_size
from slamrun.datasets.sequence import Sequence, key_bytes
from slamrun.datasets.view import Direction, PreparedView, Profile
from slamrun.errors import DatasetError

VIEW_FORMAT_VERSION = 4  # 3: a manifest of the view's files in view.json; 4: each build in a folder of its own


FRAME_FORMATS = ("png", "pgm")  # rectified frames: png is compact, pgm is fastest to write and read


def view_key(
    seq: Sequence,
    direction: Direction,
    profile: Profile,
    frame_format: str = "png",
    perturbation: Perturbation = BASELINE,
) -> str:
    """Content-addressed key: the small files in full, the frames by name and their container's size and time, and
    the perturbation (a baseline view's key has none: caches of campaigns without the axis stay valid)."""
    h = hashlib.sha256()
    fmt = frame_format if profile is Profile.rectified or not seq.fov else "-"
    layout = "" if seq.layout == "tum-mono" else f"|{seq.layout}"
    pert = "" if perturbation.is_none else f"|{perturbation.label}"
    h.update(f"v{VIEW_FORMAT_VERSION}|{direction.value}|{profile.value}|{fmt}{layout}{pert}".encode())
    for p in seq.key_files:
        h.update(key_bytes(p))
    h.update(seq.frames_stamp().encode())
    if seq.vignette is not None and seq.vignette.exists():
        st = seq.vignette.stat()
        h.update(f"{seq.vignette.name}|{st.st_size}|{st.st_mtime_ns}".encode())
    h.update("|".join(seq.frame_names).encode())
    pert = "" if perturbation.is_none else f"-{perturbation.label}"
    return f"{seq.name}-{direction.value}-{profile.value}{pert}-{h.hexdigest()[:12]}"


def prepare(
    sequence_dir: Path | Path,
    direction: Direction,
    profile: Profile,
    cache_dir: Path | str,
    workers: int = 2,
    frame_format: str = "png",
    perturbation: Perturbation = BASELINE,
) -> PreparedView:
    """The prepared view, built now if the cache lacks it (safe across threads and processes).

    Each build has a folder of its own, `<key>.<build id>` (the build's time and a random part, also in view.json),
    never used again, even when the cache was deleted meanwhile: a run compares the build it started with (its
    view's `build_id`) with what is at its view's folder when it ends. A view found damaged (a file changed, added
    or removed since it was built: `verify_view`) is not used: a new build is made beside it, so a run still
    reading the old one is not disturbed; `remove_damaged` deletes the old ones when no run is in flight.
    """
    seq = open_sequence(sequence_dir)
    cache_dir = Path(cache_dir)
    cache_dir.mkdir(parents=True, exist_ok=True)
    if frame_format not in FRAME_FORMATS:
        raise ValueError(f"frame format {frame_format!r}; expected one of {FRAME_FORMATS}")
    key = view_key(seq, direction, profile, frame_format, perturbation)
    final = _latest_generation(cache_dir, key)
    if final is not None and verify_view(final) is None:
        return PreparedView.load(final)
    with open(cache_dir / f".{key}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # one builds, the others wait here and then find it built
        final = _latest_generation(cache_dir, key)
        if final is not None and verify_view(final) is None:
            return PreparedView.load(final)
        build_id = new_build_id()
        final = cache_dir / f"{key}.{build_id}"
        tmp = cache_dir / f".{key}.tmp-{os.getpid()}"
        if tmp.exists():
            _remove(tmp)
        tmp.mkdir()
        try:
            _build(
                seq,
                direction,
                profile,
                tmp,
                workers,
                frame_format,
                whole_view(cache_dir, seq, direction.opposite, profile, frame_format, perturbation),
                perturbation,
            )
            _seal(tmp, build_id)
            os.rename(tmp, final)
        except BaseException:
            _remove(tmp)
            raise
    return PreparedView.load(final)


def whole_view(
    cache_dir: Path,
    seq: Sequence,
    direction: Direction,
    profile: Profile,
    frame_format: str,
    perturbation: Perturbation = BASELINE,
) -> Path | None:
    """The folder of the view if the cache holds it prepared and whole, else None. The whole view in the opposite
    direction (same sequence, profile and perturbation) is this view's mirror: its frames are this view's in reverse
    order (a perturbed frame depends on its index, not the direction)."""
    root = _latest_generation(Path(cache_dir), view_key(seq, direction, profile, frame_format, perturbation))
    return root if root is not None and verify_view(root) is None else None


def _link_reversed(mirror: Path, images: Path, names: list[str]) -> bool:
    """Hard-link the mirror view's frames into `images` in reverse order (no decoding, no disk); False when
    the mirror's frames are not named alike or the file system refuses links (the caller decodes then)."""
    source = mirror / PreparedView.images_dir
    n = len(names)
    try:
        for i, name in enumerate(names):
            os.link(source / names[n - 1 - i], images / name)
    except OSError:
        for name in os.listdir(images):
            os.unlink(images / name)
        return False
    return True


def new_build_id() -> str:
    """A view build's identity: its time in ns (hex, fixed width: names sort by build time) and a random part."""
    return f"{time.time_ns():016x}{secrets.token_hex(3)}"


def _latest_generation(cache_dir: Path, key: str) -> Path | None:
    """The newest build of view `key` in the cache, or None."""
    prefix = f"{key}."
    try:
        names = [n for n in os.listdir(cache_dir) if n.startswith(prefix) and not n.startswith(".")]
    except FileNotFoundError:
        return None
    found = [cache_dir / n for n in sorted(names, reverse=True) if (cache_dir / n / "view.json").exists()]
    return found[0] if found else None


def verify_view(root: Path, build_id: str | None = None) -> str | None:
    """Why a prepared view cannot be trusted (missing, another build than `build_id` where that is given, a file
    changed, added or removed since it was built), or None when it is whole. Compares names, sizes and
    modification times with the manifest in view.json."""
    try:
        meta = json.loads((root / "view.json").read_text())
    except FileNotFoundError:
        return f"{root}: missing"
    except (OSError, ValueError) as exc:
        return f"{root}/view.json unreadable ({exc})"
    if build_id is not None and meta.get("build_id") != build_id:
        return f"{root}: another build of the view (build {meta.get('build_id')}, the run had {build_id})"
    expected = {rel: (size, mtime) for rel, size, mtime in meta.get("manifest", [])}
    found = _manifest(root)
    if found == expected:
        return None
    added = sorted(found.keys() - expected.keys())
    missing = sorted(expected.keys() - found.keys())
    changed = sorted(k for k in found.keys() & expected.keys() if found[k] != expected[k])
    parts = [
        f"{len(v)} {what} (e.g. {v[0]})"
        for what, v in (("added", added), ("missing", missing), ("changed", changed))
        if v
    ]
    return f"{root}: damaged since it was prepared: " + ", ".join(parts)


def _manifest(root: Path) -> dict[str, tuple[int, int]]:
    out = {}
    for dirpath, _, files in os.walk(root):
        for name in files:
            full = os.path.join(dirpath, name)
            rel = os.path.relpath(full, root)
            if rel != "view.json":
                st = os.stat(full)
                out[rel] = (st.st_size, st.st_mtime_ns)
    return out


def _seal(root: Path, build_id: str) -> None:
    """Record the build's identity and the view's files in view.json and make them read-only (a method must not
    write the view)."""
    meta = json.loads((root / "view.json").read_text())
    meta["build_id"] = build_id
    meta["manifest"] = [[rel, size, mtime] for rel, (size, mtime) in sorted(_manifest(root).items())]
    (root / "view.json").write_text(json.dumps(meta))
    for dirpath, dirs, files in os.walk(root):
        for name in files:
            os.chmod(os.path.join(dirpath, name), 0o444)
        for name in dirs:
            os.chmod(os.path.join(dirpath, name), 0o555)
    os.chmod(root, 0o555)


def _remove(root: Path) -> None:
    """rmtree of a (read-only) view."""
    try:
        os.chmod(root, 0o755)
    except OSError:
        pass
    for dirpath, dirs, _ in os.walk(root):
        for name in dirs:
            try:
                os.chmod(os.path.join(dirpath, name), 0o755)
            except OSError:
                pass
    shutil.rmtree(root, ignore_errors=True)


def remove_damaged(cache_dir: Path) -> int:
    """Delete every view in the cache that `verify_view` finds damaged and that a newer generation
    replaces; call it when no run is in flight. Returns how many were removed."""
    cache_dir = Path(cache_dir)
    if not cache_dir.is_dir():
        return 0
    removed = 0
    for p in cache_dir.iterdir():
        if p.is_dir() and not p.name.startswith(".") and verify_view(p) is not None:
            _remove(p)
            removed += 1
    return removed


def _build(
    seq: Sequence,
    direction: Direction,
    profile: Profile,
    out: Path,
    workers: int,
    frame_format: str,
    mirror: Path | None = None,
    perturbation: Perturbation = BASELINE,
) -> None:
    """Write the view into `out`; its frames are hard links to `mirror`'s (the other direction's view), in
    reverse order, when one is given and links work, else decoded (perturbed, rectified) from the sequence. A
    view without some frames (frame_drop) lacks their times too: its frames and times are the kept ones."""
    kept = kept_frames(seq.n_frames, perturbation)
    n = len(kept)
    order = kept if direction is Direction.forward else kept[::-1]
    t_all = seq.timestamps
    t_first, t_last = float(t_all[0]), float(t_all[-1])
    t_orig = t_all[kept]
    t_view = t_all[order] if direction is Direction.forward else t_first + t_last - t_all[order]
    exposure = seq.exposures_ms[order] if seq.exposures_ms is not None else np.ones(n)
    (out / PreparedView.images_dir).mkdir()
    frames = _FrameWriter(seq, order, out, workers, mirror, perturbation)
    if profile is Profile.native and seq.fov:  # the original frames and the FOV (or pinhole) calibration
        names, width, height, pinhole = frames.native()
    else:  # rectified; also the native view of a camera model that methods' calibration files cannot express
        names, width, height, pinhole = frames.rectified(frame_format)
    _write_lists(out, seq, direction, t_orig, t_view, exposure, names)
    meta = {
        "sequence": seq.name,
        "source": str(seq.root),
        "direction": direction.value,
        "profile": profile.value,
        "n_frames": n,
        "perturbation": perturbation.label,
        "t_first": t_first,
        "t_last": t_last,
        "width": width,
        "height": height,
        "pinhole": list(pinhole) if pinhole else None,
        "format_version": VIEW_FORMAT_VERSION,
        "frame_suffix": Path(names[0]).suffix,
        "photometric": profile is Profile.native and seq.fov and seq.photometric,
        "layout": seq.layout,
    }
    (out / "view.json").write_text(json.dumps(meta, indent=1))


class _FrameWriter:
    """A view's frames, in the view's order (`order`: the sequence's frame each view frame is; frames not in it
    are left out), written into `out`/images on `workers` threads, or hard-linked from `mirror` (the other
    direction's view); each perturbed as `perturbation` says (after decoding, before rectification: at the camera)."""

    def __init__(
        self,
        seq: Sequence,
        order: np.ndarray,
        out: Path,
        workers: int,
        mirror: Path | None,
        perturbation: Perturbation = BASELINE,
    ):
        self.seq, self.out, self.workers, self.mirror = seq, out, workers, mirror
        self.perturbation = perturbation
        self.images = out / PreparedView.images_dir
        self.inverse = {int(orig): i for i, orig in enumerate(order)}
        self.index = {name: j for j, name in enumerate(seq.frame_names)}  # a frame's index in the sequence
        self.camera: CameraFile = seq.camera
        if perturbation.scale != 1.0:  # the calibration of the resized frames
            cam = seq.camera.camera
            try:
                self.camera = scaled_camera_file(seq.camera, *scaled_size(cam.width, cam.height, perturbation))
            except DatasetError as exc:
                raise DatasetError(f"{seq.root}: {perturbation.label}: {exc}") from None

    def _each(self, names: list[str], write: Callable[[Path, str, bytes], None]) -> None:
        if self.mirror is not None and _link_reversed(self.mirror, self.images, names):
            return

        def one(item: tuple[int, tuple[str, bytes]]) -> None:
            j, (name, data) = item
            if j in self.inverse:  # a dropped frame is not written
                write(self.images / names[self.inverse[j]], name, data)

        with ThreadPoolExecutor(max(1, self.workers)) as pool:
            list(pool.map(one, enumerate(self.seq.read_bytes())))

    def _perturbed(self, name: str, img: np.ndarray) -> np.ndarray:
        return perturb_frame(img, self.perturbation, self.seq.name, self.index[name], self.seq.n_frames)

    def native(self) -> tuple[list[str], int, int, None]:
        """The original frames, each checked to decode, and the sequence's calibration files; perturbed frames are
        written losslessly as PNG, with the calibration (and vignette) of their size."""
        seq, cam, out, pert = self.seq, self.camera, self.out, self.perturbation
        ext = ".png" if pert.changes_pixels else Path(seq.frame_names[0]).suffix.lower()
        names = [f"{i:06d}{ext}" for i in range(len(self.inverse))]

        def copy(dest: Path, name: str, data: bytes) -> None:
            img = seq.decode(name, data, cv2.IMREAD_UNCHANGED)  # a frame a method cannot read: the dataset's problem
            if pert.changes_pixels:
                cv2.imwrite(str(dest), self._perturbed(name, img), [cv2.IMWRITE_PNG_COMPRESSION, 1])
            else:
                dest.write_bytes(data)

        self._each(names, copy)
        if seq.camera_txt is not None and cam is seq.camera:
            shutil.copyfile(seq.camera_txt, out / PreparedView.camera)
        else:
            write_camera_txt(out / PreparedView.camera, cam.camera, cam.output_mode, (cam.out_width, cam.out_height))
        if seq.pcalib is not None and seq.pcalib.exists():
            shutil.copyfile(seq.pcalib, out / seq.pcalib.name)
        if seq.vignette is not None and seq.vignette.exists():
            self._vignette(seq.vignette, out / seq.vignette.name)
        return names, cam.camera.width, cam.camera.height, None

    def _vignette(self, src: Path, dest: Path) -> None:
        """The vignette image, resized with the frames (a per-pixel attenuation)."""
        if self.camera is self.seq.camera:
            shutil.copyfile(src, dest)
            return
        img = cv2.imread(str(src), cv2.IMREAD_UNCHANGED)
        if img is None:
            raise DatasetError(f"{src}: does not decode as an image; expected the vignette")
        size = (self.camera.camera.width, self.camera.camera.height)
        cv2.imwrite(str(dest), cv2.resize(img, size, interpolation=cv2.INTER_AREA))

    def rectified(self, frame_format: str) -> tuple[list[str], int, int, tuple[float, float, float, float]]:
        """The frames rectified to the pinhole camera of the sequence's, and that camera's files."""
        seq, cam, out = self.seq, self.camera, self.out
        mode = "crop" if cam.output_mode == "explicit" else cam.output_mode
        problem = rectification_problem(cam)
        if problem is not None:
            raise DatasetError(f"{seq.root}: {problem}")
        dst = rectified_pinhole(cam.camera, mode, cam.out_width, cam.out_height)
        map_x, map_y = rectification_maps(cam.camera, dst)
        if not (np.isfinite(map_x).all() and np.isfinite(map_y).all()):
            raise DatasetError(f"{seq.root}: the camera cannot be rectified: its rectification maps are not finite")
        names = [f"{i:06d}.{frame_format}" for i in range(len(self.inverse))]
        params = [cv2.IMWRITE_PNG_COMPRESSION, 1] if frame_format == "png" else []

        def rectify(dest: Path, name: str, data: bytes) -> None:
            img = self._perturbed(name, seq.decode(name, data))
            rect = cv2.remap(img, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
            cv2.imwrite(str(dest), rect, params)

        self._each(names, rectify)
        (out / PreparedView.camera).write_text(dst.camera_txt())
        pinhole = {"width": dst.width, "height": dst.height, "fx": dst.fx, "fy": dst.fy, "cx": dst.cx, "cy": dst.cy}
        described = pinhole | {"K": dst.K().tolist(), "distortion": [0.0, 0.0, 0.0, 0.0, 0.0]}
        (out / "camera_pinhole.json").write_text(json.dumps(described, indent=1))
        return names, dst.width, dst.height, (dst.fx, dst.fy, dst.cx, dst.cy)


def _write_lists(
    out: Path,
    seq: Sequence,
    direction: Direction,
    t_orig: np.ndarray,
    t_view: np.ndarray,
    exposure: np.ndarray,
    names: list[str],
) -> None:
    """The view's frame lists and times, in every form the methods read."""
    n = len(names)
    with open(out / PreparedView.times, "w") as f:
        for i in range(n):
            f.write(f"{i:06d} {t_view[i]:.6f} {exposure[i]:.6f}\n")
    with open(out / "original_times.txt", "w") as f:
        f.writelines(f"{v!r}\n" for v in t_orig.tolist())
    with open(out / PreparedView.times_single, "w") as f:
        f.writelines(f"{t_view[i]:.6f}\n" for i in range(n))
    with open(out / PreparedView.rgb, "w") as f:
        f.write(
            f"# prepared view of {seq.name} ({direction.value})\n# frames in presentation order\n# timestamp filename\n"
        )
        f.writelines(f"{t_view[i]:.6f} {PreparedView.images_dir}/{names[i]}\n" for i in range(n))
    with open(out / PreparedView.images_list, "w") as f:
        f.writelines(f"{t_view[i]:.6f} {PreparedView.images_dir}/{names[i]}\n" for i in range(n))


def disk_usage(path: Path, seen: set[tuple[int, int]] | None = None) -> int:
    """Bytes of the files under `path`, each file counted once however many links it has, also across the
    calls that share `seen` (a view's frames are links to its other direction's)."""
    seen = set() if seen is None else seen
    total = 0
    for f in Path(path).rglob("*"):
        st = f.stat()
        if f.is_file() and (st.st_dev, st.st_ino) not in seen:
            seen.add((st.st_dev, st.st_ino))
            total += st.st_size
    return total
