"""ImageNet-C's fifteen corruptions at severities 1-5 (Hendrycks and Dietterich, ICLR 2019), as the
`imagecorruptions` package (1.1.2 on PyPI; its ImageNet-C code for images of any size) computes them: its parameters,
its order of random draws and its rounding (np.uint8 of the float result truncates). Written with numpy, scipy and
OpenCV only: skimage.filters.gaussian is scipy.ndimage.gaussian_filter; rgb2hsv, hsv2rgb and Pillow's box resizing
are written out; Pillow's nearest resizing and JPEG coder are OpenCV's. The package draws from numpy's global
generator (impulse noise from scikit-image's own); here each frame has its own, seeded from the spec's seed, the
sequence, the kind, the severity and the frame's index, so a view is the same on every machine.
tests/test_corruptions.py: every kind at severities 1 and 5 equal to the package's output, bit for bit, on a grey and
a colour frame, its generator seeded alike.

Each function takes an 8-bit RGB frame (H x W x 3, 32 pixels a side or more) and returns the package's float result
(0-255, before the truncation); `corrupt` turns a grey, BGR or 16-bit frame into that and back.
"""

from __future__ import annotations

import importlib.util
import math
import zlib
from collections.abc import Callable
from pathlib import Path

import numpy as np

Frame = np.ndarray
Draws = np.random.RandomState

PAPER = "Hendrycks and Dietterich 2019, ImageNet-C; the imagecorruptions package 1.1.2"


def _gaussian(x: np.ndarray, sigma, mode: str = "nearest", truncate: float = 4.0, channels: bool = False):
    """scikit-image's gaussian filter of a float image: ndimage's, not across channels when `channels`."""
    from scipy import ndimage

    s = (sigma, sigma, 0) if channels else sigma
    return ndimage.gaussian_filter(x, s, mode=mode, truncate=truncate)


def gaussian_noise(x: Frame, severity: int, rs: Draws) -> np.ndarray:
    c = (0.08, 0.12, 0.18, 0.26, 0.38)[severity - 1]
    x = np.array(x) / 255.0
    return np.clip(x + rs.normal(size=x.shape, scale=c), 0, 1) * 255


def shot_noise(x: Frame, severity: int, rs: Draws) -> np.ndarray:
    c = (60, 25, 12, 5, 3)[severity - 1]
    x = np.array(x) / 255.0
    return np.clip(rs.poisson(x * c) / float(c), 0, 1) * 255


def impulse_noise(x: Frame, severity: int, rs: Draws) -> np.ndarray:
    """Salt and pepper on `amount` of the values, half each (scikit-image's random_noise 's&p', whose generator is
    its own: a Generator seeded from this frame's draws)."""
    amount = (0.03, 0.06, 0.09, 0.17, 0.27)[severity - 1]
    rng = np.random.default_rng(rs.randint(0, 2**31))
    out = np.array(x) / 255.0
    flipped = rng.random(out.shape) <= amount
    salted = rng.random(out.shape) <= 0.5
    out[flipped & salted] = 1.0
    out[flipped & ~salted] = 0.0
    return np.clip(out, 0, 1) * 255


def _disk(radius: int, alias_blur: float) -> np.ndarray:
    import cv2

    span, ksize = (8, (3, 3)) if radius <= 8 else (radius, (5, 5))
    xs, ys = np.meshgrid(np.arange(-span, span + 1), np.arange(-span, span + 1))
    disk = np.array((xs**2 + ys**2) <= radius**2, dtype=np.float32)
    disk /= np.sum(disk)
    return cv2.GaussianBlur(disk, ksize=ksize, sigmaX=alias_blur)


def defocus_blur(x: Frame, severity: int, rs: Draws) -> np.ndarray:
    import cv2

    radius, alias = ((3, 0.1), (4, 0.5), (6, 0.5), (8, 0.5), (10, 0.5))[severity - 1]
    x = np.array(x) / 255.0
    kernel = _disk(radius, alias)
    return np.clip(np.stack([cv2.filter2D(x[:, :, d], -1, kernel) for d in range(3)], axis=2), 0, 1) * 255


def glass_blur(x: Frame, severity: int, rs: Draws) -> np.ndarray:
    """Blur, then each pixel (from the bottom right, `iterations` times) takes the value of one up to `delta` away,
    then blur again. The package's swap of two pixel views is a copy (the second assignment reads the first's
    result): so it is here. A Python loop over the pixels (sequential: a copied pixel can be copied on): about 0.3 s a
    640x480 frame per iteration."""
    sigma, delta, iterations = ((0.7, 1, 2), (0.9, 2, 1), (1, 2, 3), (1.1, 3, 2), (1.5, 4, 2))[severity - 1]
    img = np.uint8(_gaussian(np.array(x) / 255.0, sigma, channels=True) * 255)
    height, width = img.shape[:2]
    pixels = [tuple(p) for p in img.reshape(-1, 3).tolist()]
    rows, cols = range(height - delta, delta, -1), range(width - delta, delta, -1)
    for _ in range(iterations):
        draws = rs.randint(-delta, delta, size=(len(rows) * len(cols), 2)).tolist()
        k = 0
        for h in rows:
            for w in cols:
                dx, dy = draws[k]
                k += 1
                pixels[h * width + w] = pixels[(h + dy) * width + w + dx]
    img = np.array(pixels, dtype=np.uint8).reshape(height, width, 3)
    return np.clip(_gaussian(img / 255.0, sigma, channels=True), 0, 1) * 255


def _shift(image: np.ndarray, dx: int, dy: int) -> np.ndarray:
    """The image moved by (dx, dy) pixels, its edge row or column repeated into what is uncovered."""
    out = image
    if dx < 0:
        out = np.roll(image, shift=image.shape[1] + dx, axis=1)
        out[:, dx:] = out[:, dx - 1 : dx]
    elif dx > 0:
        out = np.roll(image, shift=dx, axis=1)
        out[:, :dx] = out[:, dx : dx + 1]
    if dy < 0:
        out = np.roll(out, shift=image.shape[0] + dy, axis=0)
        out[dy:, :] = out[dy - 1 : dy, :]
    elif dy > 0:
        out = np.roll(out, shift=dy, axis=0)
        out[:dy, :] = out[dy : dy + 1, :]
    return out


def _motion_blur(x: np.ndarray, radius: int, sigma: float, angle: float) -> np.ndarray:
    """The sum of the image shifted along `angle`, weighted by a half Gaussian (the package's Wand-free blur)."""
    width = radius * 2 + 1
    taps = np.arange(width)
    kernel = (np.exp(-(taps**2) / (2 * (sigma**2)))) / (np.sqrt(2 * np.pi) * sigma)
    kernel = kernel / np.sum(kernel)
    point = (width * np.sin(np.deg2rad(angle)), width * np.cos(np.deg2rad(angle)))
    hypot = math.hypot(point[0], point[1])
    blurred = np.zeros_like(x, dtype=np.float32)
    for i in range(width):
        dy = -math.ceil(((i * point[0]) / hypot) - 0.5)
        dx = -math.ceil(((i * point[1]) / hypot) - 0.5)
        if np.abs(dy) >= x.shape[0] or np.abs(dx) >= x.shape[1]:
            break  # the motion left the image
        blurred = blurred + kernel[i] * _shift(x, dx, dy)
    return blurred


def motion_blur(x: Frame, severity: int, rs: Draws) -> np.ndarray:
    radius, sigma = ((10, 3), (15, 5), (15, 8), (15, 12), (20, 15))[severity - 1]
    angle = rs.uniform(-45, 45)
    return np.clip(_motion_blur(np.array(x), radius, sigma, angle), 0, 255)


def _clipped_zoom(img: np.ndarray, factor: float) -> np.ndarray:
    """The centre of the image zoomed by `factor` (bilinear), about the image's size."""
    from scipy.ndimage import zoom

    h = int(np.ceil(img.shape[0] / float(factor)))
    top = (img.shape[0] - h) // 2
    w = int(np.ceil(img.shape[1] / float(factor)))
    left = (img.shape[1] - w) // 2
    return zoom(img[top : top + h, left : left + w], (factor, factor, 1), order=1)


_ZOOMS = (
    lambda: np.arange(1, 1.11, 0.01),
    lambda: np.arange(1, 1.16, 0.01),
    lambda: np.arange(1, 1.21, 0.02),
    lambda: np.arange(1, 1.26, 0.02),
    lambda: np.arange(1, 1.31, 0.03),
)


def zoom_blur(x: Frame, severity: int, rs: Draws) -> np.ndarray:
    factors = _ZOOMS[severity - 1]()
    x = (np.array(x) / 255.0).astype(np.float32)
    out = np.zeros_like(x)
    for factor in factors:
        layer = _clipped_zoom(x, factor)[: x.shape[0], : x.shape[1], :]
        out[: layer.shape[0], : layer.shape[1]] += layer
    return np.clip((x + out) / (len(factors) + 1), 0, 1) * 255


def snow(x: Frame, severity: int, rs: Draws) -> np.ndarray:
    import cv2

    c = (
        (0.1, 0.3, 3, 0.5, 10, 4, 0.8),
        (0.2, 0.3, 2, 0.5, 12, 4, 0.7),
        (0.55, 0.3, 4, 0.9, 12, 8, 0.7),
        (0.55, 0.3, 4.5, 0.85, 12, 8, 0.65),
        (0.55, 0.3, 2.5, 0.85, 12, 12, 0.55),
    )[severity - 1]
    x = np.array(x, dtype=np.float32) / 255.0
    layer = rs.normal(size=x.shape[:2], loc=c[0], scale=c[1])
    layer = _clipped_zoom(layer[..., np.newaxis], c[2])
    layer[layer < c[3]] = 0
    layer = np.clip(layer.squeeze(), 0, 1)
    layer = _motion_blur(layer, radius=c[4], sigma=c[5], angle=rs.uniform(-135, -45))
    layer = np.round(layer * 255).astype(np.uint8) / 255.0
    layer = layer[..., np.newaxis][: x.shape[0], : x.shape[1], :]
    grey = cv2.cvtColor(x, cv2.COLOR_RGB2GRAY).reshape(x.shape[0], x.shape[1], 1)
    x = c[6] * x + (1 - c[6]) * np.maximum(x, grey * 1.5 + 0.5)
    return np.clip(x + layer + np.rot90(layer, k=2), 0, 1) * 255


def frost_pictures() -> list[Path] | None:
    """The package's five frost pictures that its frost draws from (frost1-5; frost6 is never drawn), from the
    installed `imagecorruptions` package (its data, not its code: `pip install --no-deps imagecorruptions==1.1.2`);
    None where it is not installed."""
    spec = importlib.util.find_spec("imagecorruptions")
    if spec is None or not spec.submodule_search_locations:
        return None
    folder = Path(next(iter(spec.submodule_search_locations))) / "frost"
    files = [folder / f"frost{i}.{'png' if i <= 3 else 'jpg'}" for i in range(1, 6)]
    return files if all(f.is_file() for f in files) else None


def frost(x: Frame, severity: int, rs: Draws) -> np.ndarray:
    import cv2

    weight, frost_weight = ((1, 0.4), (0.8, 0.6), (0.7, 0.7), (0.65, 0.7), (0.6, 0.75))[severity - 1]
    pictures = frost_pictures()
    if pictures is None:
        raise FileNotFoundError("frost needs the imagecorruptions package's frost pictures")
    picture = cv2.imread(str(pictures[rs.randint(5)]))
    ph, pw = picture.shape[:2]
    h, w = np.array(x).shape[:2]
    scale = 1.0
    if ph < h and pw >= w:
        scale = h / ph
    elif ph >= h and pw < w:
        scale = w / pw
    elif ph < h and pw < w:
        scale = np.maximum(h / ph, w / pw)
    scale *= 1.1
    size = (int(np.ceil(pw * scale)), int(np.ceil(ph * scale)))
    picture = cv2.resize(picture, dsize=size, interpolation=cv2.INTER_CUBIC)
    top, left = rs.randint(0, picture.shape[0] - h), rs.randint(0, picture.shape[1] - w)
    picture = picture[top : top + h, left : left + w][..., [2, 1, 0]]
    return np.clip(weight * np.array(x) + frost_weight * picture, 0, 255)


def _plasma_fractal(size: int, decay: float, rs: Draws) -> np.ndarray:
    """A diamond-square height map, `size` a power of two, scaled to 0-1."""
    grid = np.empty((size, size), dtype=np.float64)
    grid[0, 0] = 0
    step, wibble = size, 100.0

    def wibbled(array: np.ndarray) -> np.ndarray:
        return array / 4 + wibble * rs.uniform(-wibble, wibble, array.shape)

    while step >= 2:
        corners = grid[0:size:step, 0:size:step]
        squares = corners + np.roll(corners, shift=-1, axis=0)
        squares += np.roll(squares, shift=-1, axis=1)
        grid[step // 2 : size : step, step // 2 : size : step] = wibbled(squares)
        centres = grid[step // 2 : size : step, step // 2 : size : step]
        corners = grid[0:size:step, 0:size:step]
        left = centres + np.roll(centres, 1, axis=0) + (corners + np.roll(corners, -1, axis=1))
        grid[0:size:step, step // 2 : size : step] = wibbled(left)
        top = centres + np.roll(centres, 1, axis=1) + (corners + np.roll(corners, -1, axis=0))
        grid[step // 2 : size : step, 0:size:step] = wibbled(top)
        step //= 2
        wibble /= decay
    grid -= grid.min()
    return grid / grid.max()


def fog(x: Frame, severity: int, rs: Draws) -> np.ndarray:
    strength, decay = ((1.5, 2), (2.0, 2), (2.5, 1.7), (2.5, 1.5), (3.0, 1.4))[severity - 1]
    shape = np.array(x).shape
    side = int(np.max(shape))
    size = 1 if side == 0 else 2 ** (side - 1).bit_length()
    x = np.array(x) / 255.0
    top = x.max()
    x += strength * _plasma_fractal(size, decay, rs)[: shape[0], : shape[1]][..., np.newaxis]
    return np.clip(x * top / (top + strength), 0, 1) * 255


def _rgb2hsv(rgb: np.ndarray) -> np.ndarray:
    """scikit-image's rgb2hsv of a float image (hue and saturation 0 where the pixel is grey)."""
    out = np.empty_like(rgb)
    v = rgb.max(-1)
    delta = np.ptp(rgb, -1)
    with np.errstate(invalid="ignore", divide="ignore"):
        s = delta / v
        s[delta == 0.0] = 0.0
        for channel, offset, a, b in ((0, 0.0, 1, 2), (1, 2.0, 2, 0), (2, 4.0, 0, 1)):
            idx = rgb[..., channel] == v
            out[idx, 0] = offset + (rgb[idx, a] - rgb[idx, b]) / delta[idx]
        h = (out[..., 0] / 6.0) % 1.0
    h[delta == 0.0] = 0.0
    out[..., 0], out[..., 1], out[..., 2] = h, s, v
    out[np.isnan(out)] = 0
    return out


def _hsv2rgb(hsv: np.ndarray) -> np.ndarray:
    """scikit-image's hsv2rgb."""
    h, s, v = hsv[..., 0], hsv[..., 1], hsv[..., 2]
    sector = np.floor(h * 6)
    f = h * 6 - sector
    p, q, t = v * (1 - s), v * (1 - f * s), v * (1 - (1 - f) * s)
    sector = np.stack([sector] * 3, axis=-1).astype(np.uint8) % 6
    choices = [(v, t, p), (q, v, p), (p, v, t), (p, q, v), (t, p, v), (v, p, q)]
    return np.choose(sector, np.stack([np.stack(c, axis=-1) for c in choices]))


def brightness(x: Frame, severity: int, rs: Draws) -> np.ndarray:
    c = (0.1, 0.2, 0.3, 0.4, 0.5)[severity - 1]
    hsv = _rgb2hsv(np.array(x) / 255.0)
    hsv[:, :, 2] = np.clip(hsv[:, :, 2] + c, 0, 1)
    return np.clip(_hsv2rgb(hsv), 0, 1) * 255


def contrast(x: Frame, severity: int, rs: Draws) -> np.ndarray:
    c = (0.4, 0.3, 0.2, 0.1, 0.05)[severity - 1]
    x = np.array(x) / 255.0
    means = np.mean(x, axis=(0, 1), keepdims=True)
    return np.clip((x - means) * c + means, 0, 1) * 255


def elastic_transform(x: Frame, severity: int, rs: Draws) -> np.ndarray:
    from scipy.ndimage import map_coordinates

    image = np.array(x, dtype=np.float32) / 255.0
    shape = image.shape
    sigma = np.array(shape[:2]) * 0.01
    alpha = (250 * 0.05, 250 * 0.065, 250 * 0.085, 250 * 0.1, 250 * 0.12)[severity - 1]
    most = shape[0] * 0.005  # the package bounds both displacements by the height's share
    dx = (_gaussian(rs.uniform(-most, most, size=shape[:2]), sigma, mode="reflect", truncate=3) * alpha).astype(
        np.float32
    )
    dy = (_gaussian(rs.uniform(-most, most, size=shape[:2]), sigma, mode="reflect", truncate=3) * alpha).astype(
        np.float32
    )
    dx, dy = dx[..., np.newaxis], dy[..., np.newaxis]
    cols, rows, chans = np.meshgrid(np.arange(shape[1]), np.arange(shape[0]), np.arange(shape[2]))
    indices = np.reshape(rows + dy, (-1, 1)), np.reshape(cols + dx, (-1, 1)), np.reshape(chans, (-1, 1))
    return np.clip(map_coordinates(image, indices, order=1, mode="reflect").reshape(shape), 0, 1) * 255


def _box_weights(size_in: int, size_out: int) -> np.ndarray:
    """Pillow's BOX resampling of one axis as an (out x in) matrix of its 8-bit fixed-point weights: each output
    pixel the mean of the input pixels whose centres lie within it (the filter at pixel centres, not their areas)."""
    bits = 22  # Pillow's PRECISION_BITS for 8-bit images: 32 - 8 - 2
    scale = size_in / size_out
    support = 0.5 * max(scale, 1.0)
    out = np.zeros((size_out, size_in), dtype=np.int64)
    for i in range(size_out):
        centre = (i + 0.5) * scale
        lo, hi = max(int(centre - support + 0.5), 0), min(int(centre + support + 0.5), size_in)
        taps = (np.arange(lo, hi) - centre + 0.5) / max(scale, 1.0)
        w = ((taps > -0.5) & (taps <= 0.5)).astype(np.float64)
        if w.sum():
            w /= w.sum()
        out[i, lo:hi] = (0.5 + w * (1 << bits)).astype(np.int64)
    return out


def _pillow_box(x: np.ndarray, width: int, height: int) -> np.ndarray:
    """An 8-bit H x W x 3 image resized to `width` x `height` as Pillow's Image.resize(BOX) does: the horizontal
    pass first, rounded to 8 bits, then the vertical, in its fixed point (equal to Pillow's, bit for bit)."""
    bits, half = 22, 1 << 21
    rows = np.einsum("oi,hic->hoc", _box_weights(x.shape[1], width), x.astype(np.int64))
    rows = np.clip((rows + half) >> bits, 0, 255)
    out = np.einsum("oi,iwc->owc", _box_weights(x.shape[0], height), rows)
    return np.clip((out + half) >> bits, 0, 255).astype(np.uint8)


def pixelate(x: Frame, severity: int, rs: Draws) -> np.ndarray:
    """Box-filtered down to the severity's share of each side (Pillow's BOX, written out), then up again by nearest
    neighbour (OpenCV's exact nearest: Pillow's NEAREST)."""
    import cv2

    c = (0.6, 0.5, 0.4, 0.3, 0.25)[severity - 1]
    h, w = np.array(x).shape[:2]
    small = _pillow_box(np.array(x), int(w * c), int(h * c))
    return cv2.resize(small, (w, h), interpolation=cv2.INTER_NEAREST_EXACT).astype(np.float64)


def jpeg_compression(x: Frame, severity: int, rs: Draws) -> np.ndarray:
    """Encoded as JPEG at the severity's quality and decoded (Pillow's libjpeg at its defaults; here OpenCV's)."""
    import cv2

    quality = (25, 18, 15, 10, 7)[severity - 1]
    ok, data = cv2.imencode(".jpg", cv2.cvtColor(np.array(x), cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, quality])
    if not ok:
        raise ValueError("JPEG encoding failed")
    return cv2.cvtColor(cv2.imdecode(data, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB).astype(np.float64)


CORRUPTIONS: dict[str, Callable[[Frame, int, Draws], np.ndarray]] = {
    f.__name__: f
    for f in (
        gaussian_noise,
        shot_noise,
        impulse_noise,
        defocus_blur,
        glass_blur,
        motion_blur,
        zoom_blur,
        snow,
        frost,
        fog,
        brightness,
        contrast,
        elastic_transform,
        pixelate,
        jpeg_compression,
    )
}  # ImageNet-C's fifteen, in its order: noise, blur, weather, digital


# CPU seconds per megapixel of frame, measured at severity 3 on a 640x480 grey frame on one core of a 2-core machine
# (2026-11-29, with a test suite beside): what `slamrun plan` counts for a view's preparation. Glass blur's pixel loop
# is the slow one: about 0.7 s a 640x480 frame.
SECONDS_PER_MEGAPIXEL = {
    "gaussian_noise": 0.05, "shot_noise": 0.16, "impulse_noise": 0.03, "defocus_blur": 0.06, "glass_blur": 2.2,
    "motion_blur": 0.06, "zoom_blur": 0.8, "snow": 0.1, "frost": 0.03, "fog": 0.05, "brightness": 0.3,
    "contrast": 0.02, "elastic_transform": 0.21, "pixelate": 0.9, "jpeg_compression": 0.01,
}  # fmt: skip


def draws(seed: int, sequence: str, name: str, severity: int, index: int) -> Draws:
    """Frame `index`'s generator: from the seed, the sequence, the corruption, the severity and the frame alone."""
    tag = zlib.crc32(f"{sequence}|{name}|{severity}".encode())
    return np.random.RandomState([seed & 0xFFFFFFFF, tag, index])


def corrupt(img: np.ndarray, name: str, severity: int, rs: Draws) -> np.ndarray:
    """A frame (grey or BGR, 8 or 16 bit, at least 32 pixels a side) corrupted by `name` at `severity`, in its own
    type: a grey frame as the package corrupts one (the grey value in all three channels) and back to grey by the
    luma weights (OpenCV's RGB2GRAY); a 16-bit frame at 8 bits (value / 257, rounded) and back (x 257)."""
    import cv2

    if min(img.shape[:2]) < 32:
        raise ValueError(f"ImageNet-C's {name} is defined on frames of 32 pixels a side or more, not {img.shape[:2]}")
    sixteen = img.dtype == np.uint16
    eight = np.rint(img / 257.0).astype(np.uint8) if sixteen else img
    grey = eight.ndim == 2 or eight.shape[2] == 1
    rgb = np.stack((eight.reshape(eight.shape[:2]),) * 3, axis=-1) if grey else cv2.cvtColor(eight, cv2.COLOR_BGR2RGB)
    out = np.uint8(CORRUPTIONS[name](rgb, severity, rs))
    out = cv2.cvtColor(out, cv2.COLOR_RGB2GRAY).reshape(img.shape) if grey else cv2.cvtColor(out, cv2.COLOR_RGB2BGR)
    return (out.astype(np.uint16) * 257) if sixteen else out
