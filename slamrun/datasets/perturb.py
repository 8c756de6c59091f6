"""Perturbed views: the same frames made worse in one named way (noise, blur, exposure, dropped frames, a lower
resolution, JPEG compression), at a level, for robustness campaigns. Pure functions of a frame, its index in the
sequence and a seed: a view's frames are the same pixels on every machine, and a sequence's forward and backward
views hold the same perturbed frames (the noise of frame i does not depend on the direction it is played in).

`none` is the baseline: the ordinary view. Methods see ordinary frames; the view's camera follows a change of
resolution; a dropped frame is absent from the view (its time too), never repeated.

A schedule makes a perturbation come and go over the sequence's frames (by their index in the sequence, so both
directions hold the same frames): `all` (every frame, the default), `burst:N/M` (the last N frames of every M: a
method starts on ordinary frames, meets N bad ones, then M - N good ones), `ramp` (from the ordinary frame at the
first to the level at the last). A burst frame is the static view's frame; a scheduled perturbation is a condition of
its own in the results (`perturbation` `gaussian_noise@burst:3/10`). The random parts (noise, a blur's angle,
ImageNet-C's haze, flakes, frost crop, displacements) are drawn per frame, or `fixed`: the draws of the sequence's
first frame on every frame (a fog that stays; `fog@fixed`).
"""

from __future__ import annotations

import math
import re
import zlib
from dataclasses import dataclass

import numpy as np

from slamrun.results.vocabulary import NONE, level_text, played  # noqa: F401 - part of this module's names


@dataclass(frozen=True)
class Kind:
    """One kind of perturbation: the spec's parameter naming its levels, what it models, and the order of
    severity of its levels (`worse(a, b)`: a is the more severe)."""

    name: str
    parameter: str
    unit: str
    models: str
    baseline: float  # the level that leaves frames as they are (the x-axis' "none")
    severity: str  # "up": a higher level is worse; "down": lower is worse; "away": further from baseline (log)

    def severity_of(self, level: float) -> float:
        if self.severity == "up":
            return level
        if self.severity == "down":
            return -level
        return abs(math.log(level))

    def valid(self, level: float) -> str | None:
        """Why `level` is not a level of this kind, or None."""
        if not math.isfinite(level):
            return "not a finite number"
        if level == self.baseline:
            return "the baseline (the ordinary view), which every campaign runs: leave it out"
        lo, hi, integer = _RANGES[self.name]
        if integer and level != int(level):
            return "expected a whole number"
        if not lo <= level <= hi:
            return f"expected {lo:g} to {hi:g}"
        return None


IMAGENET_C = "imagenet_c."  # the prefix of ImageNet-C's kinds: imagenet_c.fog at severity 1-5
# ImageNet-C's fifteen (slamrun.datasets.corruptions.CORRUPTIONS), what each models (Hendrycks and Dietterich 2019)
IMAGENET_C_MODELS = {
    "gaussian_noise": "sensor noise in low light: Gaussian noise per pixel and channel",
    "shot_noise": "photon (Poisson) noise",
    "impulse_noise": "salt-and-pepper noise (bit errors)",
    "defocus_blur": "an out-of-focus lens: a disk kernel",
    "glass_blur": "frosted glass: blur, pixels displaced locally, blur again",
    "motion_blur": "camera shake: a directional blur at an angle drawn per frame",
    "zoom_blur": "a camera moving fast towards the scene: zoomed copies averaged",
    "snow": "falling snow: a blurred flake layer over a brightened frame",
    "frost": "frost on the lens: a frost picture blended in",
    "fog": "fog: a fractal haze added, contrast reduced",
    "brightness": "daylight: value raised in HSV",
    "contrast": "low contrast: values drawn towards the frame's mean",
    "elastic_transform": "local elastic distortion of the frame",
    "pixelate": "a low-resolution upsampled camera: box down, nearest up",
    "jpeg_compression": "lossy compression at low JPEG quality",
}

_RANGES = {  # (lowest, highest, whole numbers only)
    "gaussian_noise": (0.1, 128.0, False),
    "motion_blur": (2, 101, True),
    "exposure": (0.05, 20.0, False),
    "frame_drop": (2, 1000, True),
    "resolution": (0.05, 0.95, False),
    "jpeg": (1, 95, True),
} | {IMAGENET_C + name: (1, 5, True) for name in IMAGENET_C_MODELS}

KINDS: dict[str, Kind] = {
    k.name: k
    for k in (
        Kind(
            "gaussian_noise",
            "sigma",
            "grey levels of 255",
            "sensor noise: zero-mean Gaussian noise of standard deviation `sigma`, independent per pixel and frame",
            0.0,
            "up",
        ),
        Kind(
            "motion_blur",
            "length_px",
            "pixels",
            "camera shake during the exposure: a line kernel `length_px` long, at an angle drawn per frame",
            1.0,
            "up",
        ),
        Kind(
            "exposure",
            "gain",
            "factor",
            "a wrong exposure: intensities times `gain`, saturated (under 1 darker, over 1 brighter and clipped); "
            "the exposure times a method is given stay the original ones",
            1.0,
            "away",
        ),
        Kind(
            "frame_drop",
            "every",
            "frames",
            "lost frames: every `every`-th frame of the sequence is absent (2: half the frame rate), its time too",
            math.inf,
            "down",
        ),
        Kind(
            "resolution",
            "scale",
            "factor",
            "a lower-resolution camera: frames resized by `scale` (area interpolation), the calibration with them",
            1.0,
            "down",
        ),
        Kind(
            "jpeg",
            "quality",
            "JPEG quality",
            "lossy compression: each frame encoded as JPEG at `quality` and decoded (stored losslessly after)",
            100.0,
            "down",
        ),
        *(
            Kind(IMAGENET_C + name, "severity", "ImageNet-C severity", f"ImageNet-C's {name}: {models}", 0.0, "up")
            for name, models in IMAGENET_C_MODELS.items()
        ),
    )
}


ALL = "all"
_BURST = re.compile(r"burst:(\d+)/(\d+)$")
UNSCHEDULED = {"resolution": "a view has one camera", "frame_drop": "a view has one frame rate"}


FIXED = "fixed"
RANDOM = ("gaussian_noise", "motion_blur") + tuple(
    IMAGENET_C + n
    for n in ("gaussian_noise", "shot_noise", "impulse_noise", "glass_blur", "motion_blur", "snow", "frost", "fog",
              "elastic_transform")
)  # fmt: skip  # the kinds with random parts: what `draws: fixed` applies to


def schedule_problem(kind: str, schedule: str) -> str | None:
    """Why `schedule` cannot apply to `kind`, or None."""
    if schedule == ALL:
        return None
    if kind in UNSCHEDULED:
        return f"{kind}: {UNSCHEDULED[kind]}, so it applies to every frame (no schedule {schedule!r})"
    m = _BURST.match(schedule)
    if m and not 1 <= int(m.group(1)) < int(m.group(2)):
        return f"schedule {schedule!r}: expected burst:N/M with 1 <= N < M (N bad frames of every M)"
    if not m and schedule != "ramp":
        return f"schedule {schedule!r}: expected all, burst:N/M or ramp (burst:N/M: the last N frames of every M)"
    return None


def kind_of(name: str) -> Kind:
    """The kind of a condition a results row names (`gaussian_noise@burst:3/10`: gaussian_noise's)."""
    return KINDS[name.partition("@")[0]]


def file_tag(name: str) -> str:
    """A condition's name in file names: `gaussian_noise-burst3of10`."""
    return name.replace("@", "-").replace("burst:", "burst").replace("/", "of")


def title_of(name: str) -> str:
    """A condition as a heading says it: `gaussian noise`, `fog (ImageNet-C)`, `gaussian noise in bursts of 3
    frames every 10`, `fog (ImageNet-C), the same draws on every frame`."""
    p = Perturbation.named(name, None)
    words = p.kind.removeprefix(IMAGENET_C).replace("_", " ") + (
        " (ImageNet-C)" if p.kind.startswith(IMAGENET_C) else ""
    )
    return (
        words + _schedule_words(p.schedule).replace(",", "", 1) + (", the same draws on every frame" if p.fixed else "")
    )


def strength(schedule: str, index: int, n_frames: int) -> float:
    """The share of its level frame `index` of the sequence (of `n_frames`) is perturbed with: 0 or 1, or a ramp's
    share from 0 at the first frame to 1 at the last."""
    if schedule == ALL:
        return 1.0
    if schedule == "ramp":
        return index / (n_frames - 1) if n_frames > 1 else 1.0
    n, m = (int(v) for v in _BURST.match(schedule).groups())
    return 1.0 if index % m >= m - n else 0.0


@dataclass(frozen=True)
class Perturbation:
    """A kind at a level (`none` at no level), with the spec's seed and the schedule it comes and goes by."""

    kind: str = NONE
    level: float | None = None
    seed: int = 0
    schedule: str = ALL
    fixed: bool = False  # the first frame's random draws on every frame

    @property
    def name(self) -> str:
        """The condition's name in the ledger and results: the kind, with its schedule and `fixed` where it has them
        (`gaussian_noise@burst:3/10@fixed`)."""
        return "@".join(
            [self.kind] + ([self.schedule] if self.schedule != ALL else []) + ([FIXED] if self.fixed else [])
        )

    @classmethod
    def named(cls, name: str, level: float | None, seed: int = 0) -> Perturbation:
        """The perturbation a results row names (`name`: Perturbation.name)."""
        if name == NONE:
            return cls()
        kind, *parts = name.split("@")
        schedule = next((x for x in parts if x != FIXED), ALL)
        return cls(kind, level, seed, schedule, FIXED in parts)

    @property
    def is_none(self) -> bool:
        return self.kind == NONE

    @property
    def label(self) -> str:
        """A name for folders and run keys: `gaussian_noise-5`, `exposure-0.5` (every digit where six would make two
        levels one name: results.vocabulary.level_text); `-s7` with a seed other than 0."""
        if self.is_none:
            return NONE
        label = f"{self.kind}-{level_text(self.level)}" + (f"-s{self.seed}" if self.seed else "")
        return label + file_tag(self.name)[len(self.kind) :]

    @property
    def changes_pixels(self) -> bool:
        return not self.is_none and self.kind != "frame_drop"

    @property
    def scale(self) -> float:
        return float(self.level) if self.kind == "resolution" else 1.0


BASELINE = Perturbation()


def kept_frames(n: int, p: Perturbation) -> np.ndarray:
    """Indices of the sequence's frames a view holds: all, or all but every `every`-th (frame_drop)."""
    idx = np.arange(n)
    if p.kind != "frame_drop":
        return idx
    every = int(p.level)
    return idx[(idx + 1) % every != 0]


def scaled_size(width: int, height: int, p: Perturbation) -> tuple[int, int]:
    return max(1, round(width * p.scale)), max(1, round(height * p.scale))


def _rng(p: Perturbation, sequence: str, index: int) -> np.random.Generator:
    """The generator of frame `index` of `sequence`: from the seed, the kind, the level and the frame alone."""
    tag = zlib.crc32(f"{sequence}|{p.kind}|{p.level!r}".encode())
    return np.random.default_rng([p.seed, tag, index])


def perturb_frame(img: np.ndarray, p: Perturbation, sequence: str, index: int, n_frames: int = 0) -> np.ndarray:
    """Frame `index` (of the sequence of `n_frames`, not of the view) perturbed as its schedule says; the same dtype
    (8 or 16 bit, grey or colour)."""
    if not p.changes_pixels:
        return img
    share = strength(p.schedule, index, n_frames)
    level = float(p.level) if share >= 1.0 else _at_share(p.kind, float(p.level), share)  # a ramp: its share
    if share <= 0.0 or level == KINDS[p.kind].baseline:
        return img
    import cv2

    if p.kind.startswith(IMAGENET_C):
        from slamrun.datasets.corruptions import corrupt, draws

        name = p.kind[len(IMAGENET_C) :]
        return corrupt(img, name, int(level), draws(p.seed, sequence, name, int(level), 0 if p.fixed else index))
    top = float(np.iinfo(img.dtype).max) if img.dtype.kind in "ui" else 1.0
    if p.kind == "gaussian_noise":  # the random parts are the static level's (p's), whatever the share
        noise = _rng(p, sequence, 0 if p.fixed else index).standard_normal(img.shape, dtype=np.float32)
        noise *= level * top / 255.0
        return _clipped(img.astype(np.float32) + noise, img.dtype, top)
    if p.kind == "exposure":
        return _clipped(img.astype(np.float32) * level, img.dtype, top)
    if p.kind == "motion_blur":
        angle = _rng(p, sequence, 0 if p.fixed else index).uniform(0.0, 180.0)
        return cv2.filter2D(img, -1, _line_kernel(int(level), angle))
    if p.kind == "resolution":
        h, w = img.shape[:2]
        return cv2.resize(img, scaled_size(w, h, p), interpolation=cv2.INTER_AREA)
    if p.kind == "jpeg":
        eight = img if img.dtype == np.uint8 else (img.astype(np.float32) * (255.0 / top)).round().astype(np.uint8)
        ok, data = cv2.imencode(".jpg", eight, [cv2.IMWRITE_JPEG_QUALITY, int(level)])
        if not ok:
            raise ValueError(f"frame {index}: JPEG encoding failed")
        back = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
        return back if img.dtype == np.uint8 else (back.astype(np.float32) * (top / 255.0)).round().astype(img.dtype)
    raise ValueError(f"unknown perturbation {p.kind!r}")


def _at_share(kind: str, level: float, share: float) -> float:
    """The level `share` of the way from the kind's baseline to `level`: linear in sigma and blur length (whole
    pixels), in the log of a gain, in JPEG quality from 100 (whole steps)."""
    base = KINDS[kind].baseline
    if kind == "exposure":
        return level**share
    if kind in ("motion_blur", "jpeg") or kind.startswith(IMAGENET_C):
        return float(round(base + (level - base) * share))
    return base + (level - base) * share


def _clipped(values: np.ndarray, dtype: np.dtype, top: float) -> np.ndarray:
    if np.dtype(dtype).kind in "ui":
        return np.clip(np.rint(values), 0, top).astype(dtype)
    return np.clip(values, 0.0, top).astype(dtype)


def _line_kernel(length: int, angle_deg: float) -> np.ndarray:
    """A normalised line of `length` pixels through the kernel's centre at `angle_deg` (a linear motion)."""
    import cv2

    size = length if length % 2 else length + 1
    k = np.zeros((size, size), np.float32)
    c = (size - 1) / 2.0
    dx, dy = math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))
    half = (length - 1) / 2.0
    p0 = (round(c - dx * half), round(c - dy * half))
    p1 = (round(c + dx * half), round(c + dy * half))
    cv2.line(k, p0, p1, 1.0, 1)
    return k / k.sum()


def describe(p: Perturbation) -> str:
    """One line for logs and captions: `gaussian noise, sigma 5`."""
    if p.is_none:
        return "none (the baseline)"
    kind = KINDS[p.kind]
    fixed = ", the same draws on every frame" if p.fixed else ""
    return f"{title_of(p.kind)}, {kind.parameter} {level_text(p.level)}" + _schedule_words(p.schedule) + fixed


def _schedule_words(schedule: str) -> str:
    """A schedule as a caption says it: `, bursts of 3 frames every 10`, `, ramped up over the sequence`."""
    if schedule == ALL:
        return ""
    if schedule == "ramp":
        return ", ramped up from none over the sequence's frames"
    n, m = _BURST.match(schedule).groups()
    return f", in bursts of {n} frames every {m}"
