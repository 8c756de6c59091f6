"""Sequence validation, prepared views, and the synthetic generator."""

import shutil
import threading
import zipfile

import cv2
import numpy as np
import pytest

from slamrun.core.trajectory import from_arrays
from slamrun.datasets.cache import prepare
from slamrun.datasets.make_synthetic import generate
from slamrun.datasets.tum_mono import open_sequence
from slamrun.datasets.view import Direction, PreparedView, Profile
from slamrun.errors import DatasetError


@pytest.fixture
def seq(tmp_path, tiny_dataset):
    dst = tmp_path / "seq"
    shutil.copytree(tiny_dataset / "seq_a", dst)
    return dst


def test_valid_sequence_opens(seq):
    s = open_sequence(seq)
    assert s.n_frames == 40 and len(s.timestamps) == 40 and s.exposures_ms is not None
    gt = s.groundtruth()
    assert len(gt) == 40 and np.isnan(gt.positions[20]).all() and np.isfinite(gt.positions[0]).all()


def test_unpacked_images_folder_is_accepted(seq):
    with zipfile.ZipFile(seq / "images.zip") as zf:
        zf.extractall(seq / "images")
    (seq / "images.zip").unlink()
    assert open_sequence(seq).n_frames == 40


@pytest.mark.parametrize(
    "damage, expected",
    [
        (lambda s: (s / "images.zip").write_bytes((s / "images.zip").read_bytes()[:5000]), "not a readable zip"),
        (lambda s: (s / "pcalib.txt").unlink(), "pcalib.txt: missing"),
        (
            lambda s: (s / "times.txt").write_text("\n".join((s / "times.txt").read_text().splitlines()[:-1])),
            "39 lines but 40 images",
        ),
        (
            lambda s: (s / "times.txt").write_text((s / "times.txt").read_text().replace("1.033333", "0.5")),
            "timestamps not strictly increasing",
        ),
        (
            lambda s: (s / "camera.txt").write_text(
                (s / "camera.txt").read_text().replace("160 120\ncrop", "320 240\ncrop")
            ),
            "input size 320x240",
        ),
        (lambda s: cv2.imwrite(str(s / "vignette.png"), np.ones((10, 10), np.uint16)), "vignette.png: 10x10"),
        (lambda s: (s / "pcalib.txt").write_text(" ".join(["1"] * 256)), "not strictly increasing"),
        (lambda s: (s / "pcalib.txt").write_text(" ".join(str(i) for i in range(255))), "255 values, expected 256"),
        (lambda s: (s / "times.txt").write_text("a b c\n"), "times.txt:1: not a number"),
    ],
    ids=[
        "truncated-zip",
        "missing-pcalib",
        "count-mismatch",
        "non-increasing",
        "camera-size",
        "vignette-size",
        "pcalib-flat",
        "pcalib-short",
        "times-garbage",
    ],
)
def test_bad_inputs_are_named(seq, damage, expected):
    damage(seq)
    with pytest.raises(DatasetError) as err:
        open_sequence(seq)
    assert expected in str(err.value)
    assert str(seq) in str(err.value)


def test_several_problems_reported_together(seq):
    (seq / "pcalib.txt").unlink()
    (seq / "vignette.png").unlink()
    with pytest.raises(DatasetError) as err:
        open_sequence(seq)
    assert "pcalib.txt: missing" in str(err.value) and "vignette.png: missing" in str(err.value)


@pytest.mark.parametrize("profile", list(Profile))
def test_views_have_every_timestamp_file(tmp_path, seq, profile):
    view = prepare(seq, Direction.forward, profile, tmp_path / "cache")
    s = open_sequence(seq)
    times = np.loadtxt(view.path(view.times), ndmin=2)
    np.testing.assert_allclose(times[:, 1], s.timestamps, atol=1e-6)
    rgb = view.path(view.rgb).read_text().splitlines()
    assert len(rgb) == 3 + 40 and all(line.startswith("#") for line in rgb[:3])
    assert (view.root / rgb[3].split()[1]).exists()
    assert len(view.path(view.images_list).read_text().splitlines()) == 40
    assert np.loadtxt(view.path(view.times_single)).shape == (40,)
    assert len(list(view.path(view.images_dir).iterdir())) == 40
    if profile is Profile.rectified:
        img = cv2.imread(str(next(view.path(view.images_dir).iterdir())), cv2.IMREAD_GRAYSCALE)
        assert img.shape == (120, 160) and view.pinhole is not None
        assert "none" in view.path(view.camera).read_text()
    else:
        assert view.path(view.pcalib).exists() and view.path(view.vignette).exists()


def test_backward_view_round_trips_timestamps_exactly(tmp_path, seq):
    view = prepare(seq, Direction.backward, Profile.native, tmp_path / "cache")
    original = open_sequence(seq).timestamps
    t_view = np.loadtxt(view.path(view.times), ndmin=2)[:, 1]
    assert np.all(np.diff(t_view) > 0)  # methods see increasing time
    np.testing.assert_allclose(t_view, (original[0] + original[-1] - original)[::-1], atol=1e-6)
    traj = from_arrays(t_view, np.zeros((40, 3)), np.tile([0, 0, 0, 1.0], (40, 1)))
    back = view.to_original(traj)
    np.testing.assert_array_equal(back.timestamps, original)  # exact, not approximately
    # The first view frame is the last original frame.
    first = sorted(view.path(view.images_dir).iterdir())[0]
    with zipfile.ZipFile(seq / "images.zip") as zf:
        assert first.read_bytes() == zf.read(sorted(zf.namelist())[-1])


def _frames(view: PreparedView) -> list[bytes]:
    return [p.read_bytes() for p in sorted(view.path(view.images_dir).iterdir())]


@pytest.mark.parametrize("profile", list(Profile))
@pytest.mark.parametrize("first", list(Direction))
def test_a_view_whose_mirror_is_prepared_links_its_frames_and_equals_a_decoded_one(tmp_path, seq, profile, first):
    """The other direction's view holds the same frames in reverse order: they are hard-linked, not decoded
    again, and the result is the view a fresh cache decodes, byte for byte."""
    second = Direction.backward if first is Direction.forward else Direction.forward
    mirror = prepare(seq, first, profile, tmp_path / "cache")
    linked = prepare(seq, second, profile, tmp_path / "cache")
    decoded = prepare(seq, second, profile, tmp_path / "fresh")
    assert _frames(linked) == _frames(decoded) == _frames(mirror)[::-1]
    mirror_frames = sorted(mirror.path(mirror.images_dir).iterdir())
    for i, p in enumerate(sorted(linked.path(linked.images_dir).iterdir())):
        assert p.stat().st_ino == mirror_frames[-1 - i].stat().st_ino
    assert sorted(q.name for q in linked.root.iterdir()) == sorted(q.name for q in decoded.root.iterdir())
    for name in ("times.txt", "rgb.txt", "camera.txt"):
        assert linked.path(name).read_text() == decoded.path(name).read_text()


def test_a_damaged_mirror_is_not_linked(tmp_path, seq):
    mirror = prepare(seq, Direction.forward, Profile.rectified, tmp_path / "cache")
    frame = sorted(mirror.path(mirror.images_dir).iterdir())[5]
    frame.chmod(0o644)
    frame.write_bytes(b"not the frame")
    view = prepare(seq, Direction.backward, Profile.rectified, tmp_path / "cache")
    decoded = prepare(seq, Direction.backward, Profile.rectified, tmp_path / "fresh")
    assert _frames(view) == _frames(decoded)
    inodes = {p.stat().st_ino for p in mirror.path(mirror.images_dir).iterdir()}
    assert not inodes & {p.stat().st_ino for p in view.path(view.images_dir).iterdir()}


def test_concurrent_prepare_builds_once(tmp_path, seq):
    views, errors = [], []

    def ask():
        try:
            views.append(prepare(seq, Direction.forward, Profile.rectified, tmp_path / "cache"))
        except Exception as exc:  # noqa: BLE001
            errors.append(exc)

    threads = [threading.Thread(target=ask) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors and len({v.root for v in views}) == 1
    assert [p.name for p in (tmp_path / "cache").iterdir() if not p.name.startswith(".")] == [views[0].root.name]
    assert PreparedView.load(views[0].root).n_frames == 40


def test_cache_key_follows_content(tmp_path, seq):
    a = prepare(seq, Direction.forward, Profile.native, tmp_path / "cache")
    assert prepare(seq, Direction.forward, Profile.native, tmp_path / "cache").root == a.root
    (seq / "times.txt").write_text((seq / "times.txt").read_text().replace(" 8.", " 9."))
    assert prepare(seq, Direction.forward, Profile.native, tmp_path / "cache").root != a.root


def test_synthetic_is_deterministic_and_valid(tmp_path):
    a = generate(tmp_path / "a", frames=30, seed=5, size=(128, 96))
    b = generate(tmp_path / "b", frames=30, seed=5, size=(128, 96))
    c = generate(tmp_path / "c", frames=30, seed=6, size=(128, 96))
    for name in ("times.txt", "camera.txt", "pcalib.txt", "groundtruthSync.txt", "images.zip"):
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    assert (a / "images.zip").read_bytes() != (c / "images.zip").read_bytes()
    s = open_sequence(a)
    gt = s.groundtruth()
    valid = np.isfinite(gt.positions).all(axis=1)
    assert valid[:6].all() and valid[-6:].all() and not valid[7:-7].any()
    # the loop closes: first and last poses coincide
    np.testing.assert_allclose(gt.positions[0], gt.positions[-1], atol=1e-9)
    # translation inside both ground-truth segments
    assert np.linalg.norm(gt.positions[5] - gt.positions[0]) > 0.1
    assert np.linalg.norm(gt.positions[-1] - gt.positions[-6]) > 0.1


def test_synthetic_frames_have_strong_gradients(tiny_dataset):
    s = open_sequence(tiny_dataset / "seq_a")
    img = next(s.frames()).astype(np.float32)
    grad = np.hypot(cv2.Sobel(img, cv2.CV_32F, 1, 0), cv2.Sobel(img, cv2.CV_32F, 0, 1))
    assert img.std() > 20 and np.median(grad) > 20


def test_disk_use_and_the_dry_runs_estimate_count_linked_frames_once(tmp_path, seq):
    from slamrun.datasets.cache import disk_usage
    from slamrun.engine.dryrun import dry_run
    from slamrun.engine.spec import CampaignSpec

    spec = CampaignSpec.model_validate(
        {
            "name": "t",
            "results": str(tmp_path / "results"),
            "cache": str(tmp_path / "cache"),
            "datasets": [{"name": "d", "path": str(seq.parent), "sequences": [seq.name]}],
            "methods": [{"name": "reference_vo"}],
            "directions": ["forward", "backward"],
        }
    )
    both = dry_run(spec)
    assert both.views_to_prepare == 2
    forward = prepare(seq, Direction.forward, Profile.rectified, tmp_path / "cache")
    one = dry_run(spec)
    assert one.views_to_prepare == 1 and one.view_bytes < 10_000  # the backward view: links and small files
    frames = disk_usage(forward.path(forward.images_dir))
    assert abs(both.view_bytes - frames) < 0.6 * frames  # one direction's frames, not two (the PNG estimate)
    backward = prepare(seq, Direction.backward, Profile.rectified, tmp_path / "cache")
    seen: set = set()
    assert disk_usage(forward.root, seen) > frames and disk_usage(backward.root, seen) < 10_000
    assert disk_usage(backward.root) > frames  # alone, its frames count
