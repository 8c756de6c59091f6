"""ImageNet-C's corruptions as slamrun computes them (slamrun/datasets/corruptions.py) against the published
implementation, the `imagecorruptions` package 1.1.2 (its numpy generator seeded alike), on sample frames of a
synthetic room (grey, and a colour frame made of three of them), at severities 1 and 5.

The package runs here with three shims for today's libraries, none touching what it computes: numpy 2 has no
`np.float_` (fog's height map; float64 given), scikit-image 0.26's gaussian takes `channel_axis=-1` for
`multichannel=True` (glass blur), a setuptools without pkg_resources (where its frost pictures are). Its impulse
noise draws from scikit-image's own unseeded generator: the test hands it the seed slamrun's draws give (`rng=`), as
slamrun does."""

from __future__ import annotations

import importlib.util
import sys
import types
from pathlib import Path

import numpy as np
import pytest

from slamrun.datasets.corruptions import CORRUPTIONS, corrupt, draws, frost_pictures

if importlib.util.find_spec("pkg_resources") is None:  # setuptools without it: the one name the package takes
    shim = types.ModuleType("pkg_resources")
    shim.resource_filename = lambda package, name: str(Path(sys.modules[package].__file__).parent / name)
    sys.modules["pkg_resources"] = shim

pytest.importorskip("skimage", reason="the reference implementation needs scikit-image (make install-dev)")
pytest.importorskip("PIL", reason="the reference implementation needs Pillow (make install-dev)")
imagecorruptions = pytest.importorskip(
    "imagecorruptions", reason="the reference implementation: pip install --no-deps imagecorruptions==1.1.2"
)

SEED = [7, 1234, 5]
# Every kind equals the package's output bit for bit on these frames (Pillow's JPEG coder and OpenCV's are both
# libjpeg-turbo at the same quality and subsampling; Pillow's box resizing is written out in its fixed point).


@pytest.fixture(scope="module")
def frames(tmp_path_factory) -> dict[str, np.ndarray]:
    import cv2

    from slamrun.datasets.make_synthetic import generate

    room = generate(tmp_path_factory.mktemp("room") / "room", frames=12, seed=5, size=(240, 180))
    import zipfile

    with zipfile.ZipFile(room / "images.zip") as z:
        names = sorted(z.namelist())[:12]
        grey = [cv2.imdecode(np.frombuffer(z.read(n), np.uint8), cv2.IMREAD_GRAYSCALE) for n in names]
    return {"grey": grey[4], "colour": np.stack([grey[2], grey[6], grey[10]], axis=-1)}


@pytest.fixture(scope="module")
def reference():
    """The package's `corrupt`, with the shims above."""
    import skimage.filters
    import skimage.util
    from imagecorruptions import corruptions as ic

    def gaussian(image, sigma=1, multichannel=None, **kw):
        return skimage.filters.gaussian(image, sigma=sigma, channel_axis=-1 if multichannel else None, **kw)

    ic.gaussian = gaussian
    if not hasattr(np, "float_"):
        np.float_ = np.float64

    def run(rgb: np.ndarray, name: str, severity: int) -> np.ndarray:
        np.random.seed(SEED)
        impulse_seed = np.random.RandomState(SEED).randint(0, 2**31)
        plain = skimage.util.random_noise
        ic.sk.util.random_noise = lambda image, **kw: plain(image, rng=impulse_seed, **kw)
        try:
            return imagecorruptions.corrupt(rgb, severity=severity, corruption_name=name)
        finally:
            ic.sk.util.random_noise = plain

    return run


def test_the_fifteen_are_imagenet_cs_in_its_order():
    assert list(CORRUPTIONS) == imagecorruptions.get_corruption_names("common")


@pytest.mark.parametrize("severity", [1, 5])
@pytest.mark.parametrize("name", list(CORRUPTIONS))
def test_each_corruption_equals_the_published_implementation(frames, reference, name, severity):
    if name == "frost":  # the package is here (the module's importorskip): so are its pictures
        assert frost_pictures() is not None
    for kind, frame in frames.items():
        rgb = np.stack((frame,) * 3, axis=-1) if frame.ndim == 2 else frame
        want = reference(rgb, name, severity)
        got = np.uint8(CORRUPTIONS[name](rgb, severity, np.random.RandomState(SEED)))
        assert got.shape == want.shape and got.dtype == want.dtype
        diff = np.abs(got.astype(int) - want.astype(int))
        assert diff.max() == 0, (kind, int(diff.max()), float((diff > 0).mean()))
        if severity == 5 and name != "brightness":
            assert (want != rgb).mean() > 0.05, "the corruption changes the frame"


def test_a_frame_keeps_its_type_and_its_draws_are_its_own(frames):
    grey = frames["grey"]
    a = corrupt(grey, "gaussian_noise", 3, draws(0, "room", "gaussian_noise", 3, 4))
    b = corrupt(grey, "gaussian_noise", 3, draws(0, "room", "gaussian_noise", 3, 4))
    c = corrupt(grey, "gaussian_noise", 3, draws(0, "room", "gaussian_noise", 3, 5))
    assert a.shape == grey.shape and a.dtype == np.uint8
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    sixteen = grey.astype(np.uint16) * 257
    out = corrupt(sixteen, "contrast", 5, draws(0, "room", "contrast", 5, 4))
    assert out.dtype == np.uint16 and np.array_equal(out % 257, np.zeros_like(out))
    bgr = frames["colour"][..., ::-1].copy()
    out = corrupt(bgr, "fog", 2, draws(0, "room", "fog", 2, 4))
    assert out.shape == bgr.shape and out.dtype == np.uint8
