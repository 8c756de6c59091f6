"""Perturbed views (issue 53): each kind's view deterministic, its camera and frame times right, forward and
backward holding the same frames; the spec's `perturbations:` and the plan's runs and keys."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from slamrun.core.camera import read_camera_txt
from slamrun.datasets.cache import prepare
from slamrun.datasets.make_synthetic import generate
from slamrun.datasets.perturb import KINDS, Perturbation, kept_frames, perturb_frame
from slamrun.datasets.view import Direction, PreparedView, Profile
from slamrun.engine.plan import plan
from slamrun.engine.spec import PERTURBATION_KINDS, CampaignSpec
from slamrun.engine.spec_file import load_spec
from slamrun.errors import SlamRunError

FORWARD, BACKWARD = Direction.forward, Direction.backward
ONE_OF_EACH = [
    Perturbation("gaussian_noise", 5.0),
    Perturbation("motion_blur", 7.0),
    Perturbation("exposure", 0.5),
    Perturbation("frame_drop", 3.0),
    Perturbation("resolution", 0.5),
    Perturbation("jpeg", 30.0),
]


@pytest.fixture(scope="module")
def room(tmp_path_factory) -> Path:
    """A small synthetic TUM-Mono sequence (FOV camera, photometric calibration)."""
    return generate(tmp_path_factory.mktemp("room") / "room", frames=31, seed=3, size=(160, 120))


def _digest(view: PreparedView) -> dict[str, str]:
    """Every file of the view but view.json (its build id and times differ by build), by content."""
    out = {}
    for p in sorted(view.root.rglob("*")):
        if p.is_file() and p.name != "view.json":
            out[str(p.relative_to(view.root))] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def _frame(view: PreparedView, i: int) -> np.ndarray:
    return cv2.imread(str(view.root / view.images_dir / f"{i:06d}{view.frame_suffix}"), cv2.IMREAD_UNCHANGED)


@pytest.mark.parametrize("profile", [Profile.native, Profile.rectified])
@pytest.mark.parametrize("pert", ONE_OF_EACH, ids=lambda p: p.label)
def test_each_perturbed_view_is_byte_identical_across_two_preparations(room, tmp_path, pert, profile):
    one = prepare(room, FORWARD, profile, tmp_path / "one", perturbation=pert)
    two = prepare(room, FORWARD, profile, tmp_path / "two", workers=1, perturbation=pert)
    assert _digest(one) == _digest(two)
    assert one.perturbation == pert.label and one.root.name.startswith(f"room-forward-{profile.value}-{pert.label}-")
    baseline = prepare(room, FORWARD, profile, tmp_path / "one")
    changed = [i for i in range(baseline.n_frames) if not np.array_equal(_frame(baseline, i), _frame(one, i))]
    if pert.kind == "frame_drop":
        assert one.n_frames < baseline.n_frames
    elif pert.kind != "resolution":  # a resized frame has another shape: compared in its own test
        assert len(changed) == baseline.n_frames, f"{pert.label} left frames as they were"


def test_a_seed_gives_other_noise_and_the_seed_is_in_the_key(room, tmp_path):
    a = prepare(room, FORWARD, Profile.native, tmp_path, perturbation=Perturbation("gaussian_noise", 5.0))
    b = prepare(room, FORWARD, Profile.native, tmp_path, perturbation=Perturbation("gaussian_noise", 5.0, seed=7))
    assert a.root != b.root and "gaussian_noise-5-s7" in b.root.name
    assert not np.array_equal(_frame(a, 0), _frame(b, 0))


@pytest.mark.parametrize("pert", ONE_OF_EACH, ids=lambda p: p.label)
def test_backward_holds_the_forward_frames_in_reverse(room, tmp_path, pert):
    fw = prepare(room, FORWARD, Profile.rectified, tmp_path, perturbation=pert)
    bw = prepare(room, BACKWARD, Profile.rectified, tmp_path, perturbation=pert)
    n = fw.n_frames
    assert bw.n_frames == n
    for i in (0, n // 2, n - 1):
        assert np.array_equal(_frame(fw, i), _frame(bw, n - 1 - i))


def test_noise_exposure_blur_and_jpeg_do_what_they_say(room, tmp_path):
    img = _frame(prepare(room, FORWARD, Profile.native, tmp_path), 10)
    assert img.dtype == np.uint8 and img.ndim == 2
    noisy = perturb_frame(img, Perturbation("gaussian_noise", 8.0), "room", 10).astype(float) - img
    unclipped = (img > 40) & (img < 215)
    assert 7.5 < noisy[unclipped].std() < 8.5 and abs(noisy[unclipped].mean()) < 0.3
    dark = perturb_frame(img, Perturbation("exposure", 0.5), "room", 10)
    assert np.abs(dark.astype(float) - np.rint(img * 0.5)).max() <= 0
    bright = perturb_frame(img, Perturbation("exposure", 2.0), "room", 10)
    assert bright[img >= 128].min() == 255  # saturated
    blurred = perturb_frame(img, Perturbation("motion_blur", 9.0), "room", 10)

    def sharpness(a):
        return cv2.Laplacian(a.astype(np.float32), cv2.CV_32F).var()

    assert sharpness(blurred) < 0.5 * sharpness(img)
    lossy = perturb_frame(img, Perturbation("jpeg", 10.0), "room", 10)
    assert lossy.shape == img.shape and lossy.dtype == img.dtype and 0 < np.abs(lossy.astype(int) - img).mean() < 20
    sixteen = (img.astype(np.uint16) * 257)[..., None].repeat(3, axis=2)  # 16-bit colour keeps its type
    for p in ONE_OF_EACH[:3] + ONE_OF_EACH[5:]:
        out = perturb_frame(sixteen, p, "room", 10)
        assert out.dtype == np.uint16 and out.shape == sixteen.shape


@pytest.mark.parametrize("profile", [Profile.native, Profile.rectified])
def test_a_lower_resolution_scales_the_frames_and_the_camera(room, tmp_path, profile):
    half = Perturbation("resolution", 0.5)
    full = prepare(room, FORWARD, profile, tmp_path)
    view = prepare(room, FORWARD, profile, tmp_path, perturbation=half)
    assert (view.width, view.height) == (80, 60) and _frame(view, 3).shape[:2] == (60, 80)
    cam = read_camera_txt(view.root / "camera.txt")
    assert (cam.camera.width, cam.camera.height) == (80, 60)
    if profile is Profile.native:  # the same lens: the FOV model's relative intrinsics, the vignette resized with it
        base = read_camera_txt(full.root / "camera.txt").camera
        assert cam.camera.fx == pytest.approx(base.fx / 2) and cam.camera.omega == base.omega
        assert (cam.camera.cx + 0.5) == pytest.approx((base.cx + 0.5) / 2)
        assert cv2.imread(str(view.root / "vignette.png"), cv2.IMREAD_UNCHANGED).shape[:2] == (60, 80)
    else:  # the rectified pinhole of the scaled camera: half the focal length (within a pixel's rounding)
        pin = json.loads((view.root / "camera_pinhole.json").read_text())
        base = json.loads((full.root / "camera_pinhole.json").read_text())
        assert (pin["width"], pin["height"]) == (80, 60)
        assert pin["fx"] == pytest.approx(base["fx"] / 2, rel=0.02) and pin["fy"] == pytest.approx(
            base["fy"] / 2, rel=0.02
        )


@pytest.mark.parametrize("direction", [FORWARD, BACKWARD])
def test_dropped_frames_are_absent_with_their_times(room, tmp_path, direction):
    drop = Perturbation("frame_drop", 3.0)
    full = prepare(room, direction, Profile.native, tmp_path)
    view = prepare(room, direction, Profile.native, tmp_path, perturbation=drop)
    kept = kept_frames(31, drop)
    assert list(kept[:6]) == [0, 1, 3, 4, 6, 7] and len(kept) == 21 and view.n_frames == 21
    times = np.loadtxt(view.root / view.times, ndmin=2)
    all_times = np.loadtxt(full.root / full.times, ndmin=2)
    order = kept if direction is FORWARD else (30 - kept)[::-1]  # the full view's rows these frames are
    assert np.array_equal(times[:, 1], all_times[order, 1])  # the same instants: nothing repeated, nothing shifted
    assert np.all(np.diff(times[:, 1]) > 0) and times[:, 0].tolist() == list(range(21))
    assert len(list((view.root / "images").iterdir())) == 21
    original = view.original_timestamps()
    seq_times = np.loadtxt(room / "times.txt", ndmin=2)[:, 1]
    assert np.array_equal(original, seq_times[kept])
    for i in (0, 5, 20):  # the frames are the kept ones, unchanged
        src = order[i]
        assert np.array_equal(_frame(view, i), _frame(full, int(src)))


# ------------------------------------------------------------------ the spec and the plan


def _spec(tmp_path: Path, **kw) -> Path:
    generate(tmp_path / "data" / "seq_a", frames=30, seed=1, size=(160, 120))
    spec = {
        "name": "p",
        "results": str(tmp_path / "results"),
        "cache": str(tmp_path / "cache"),
        "datasets": [{"name": "synth", "path": str(tmp_path / "data"), "sequences": ["seq_a"]}],
        "methods": [{"name": "reference_vo"}],
        "trials": 2,
        **kw,
    }
    path = tmp_path / "spec.yaml"
    path.write_text(yaml.safe_dump(spec))
    return path


def test_the_spec_names_each_kind_the_schema_knows():
    from slamrun.datasets.perturb import IMAGENET_C, IMAGENET_C_MODELS

    own = {k for k in KINDS if not k.startswith(IMAGENET_C)}
    assert set(PERTURBATION_KINDS.__args__) == own | set(IMAGENET_C_MODELS)
    assert {k for k in KINDS if k.startswith(IMAGENET_C)} == {IMAGENET_C + n for n in IMAGENET_C_MODELS}


@pytest.mark.parametrize(
    ("entry", "expected"),
    [
        ({"kind": "gaussian_noise", "gain": [2]}, "gaussian_noise takes `sigma`, not gain"),
        ({"kind": "jpeg", "quality": [0]}, "jpeg: quality 0: expected 1 to 95"),
        ({"kind": "frame_drop", "every": [2, 2]}, "frame_drop: the levels of every repeat"),
        ({"kind": "exposure"}, "exposure: give its levels"),
        ({"kind": "exposure", "gain": [1.0]}, "exposure: gain 1.0: the baseline"),
        ({"kind": "motion_blur", "length_px": [2.5]}, "length_px[0]: Input should be a valid integer"),
        ({"kind": "gaussian_nosie", "sigma": [2]}, "did you mean 'gaussian_noise'"),
        ({"kind": "resolution", "scale": [0.5], "sigam": 2}, "unknown key; did you mean 'sigma'"),
    ],
)
def test_a_wrong_perturbation_is_named_before_anything_runs(tmp_path, entry, expected):
    with pytest.raises(SlamRunError) as err:
        load_spec(_spec(tmp_path, perturbations=[entry]))
    assert "perturbations[0]" in str(err.value) and expected in str(err.value)


def test_the_plan_adds_each_level_beside_an_unchanged_baseline(tmp_path):
    plain = plan(load_spec(_spec(tmp_path)))
    axis = [{"kind": "gaussian_noise", "sigma": [2, 5]}, {"kind": "frame_drop", "every": 2}]
    runs = plan(load_spec(_spec(tmp_path, perturbations=axis)))
    assert len(runs) == len(plain) * (1 + 3)  # the baseline and three levels
    base = [r for r in runs if r.perturbation.is_none]
    assert [r.key.id for r in base] == [r.key.id for r in plain]  # a campaign without the axis keeps its keys
    noisy = next(r for r in runs if r.perturbation.label == "gaussian_noise-2")
    assert "/forward+gaussian_noise-2/" in noisy.key.id or "/backward+gaussian_noise-2/" in noisy.key.id
    assert noisy.key.relpath.parts[3] == noisy.key.played  # one folder level, as a baseline run's direction
    assert len({r.key.id for r in runs}) == len(runs)
    first_trial = [r for r in runs if r.key.trial == 0]
    assert all(r.perturbation.is_none for r in first_trial[: len(base) // 2])  # the baseline first in each trial


def test_a_dataset_names_its_own_perturbations(tmp_path):
    spec = load_spec(_spec(tmp_path, perturbations=[{"kind": "jpeg", "quality": [30]}]))
    raw = spec.model_dump(mode="json")
    raw["datasets"][0]["perturbations"] = []
    runs = plan(CampaignSpec.model_validate(raw))
    assert all(r.perturbation.is_none for r in runs)
    raw["perturbation_seed"] = 9
    raw["datasets"][0]["perturbations"] = [{"kind": "exposure", "gain": [0.5, 2.0]}]
    labels = {r.perturbation.label for r in plan(CampaignSpec.model_validate(raw))}
    assert labels == {"none", "exposure-0.5-s9", "exposure-2-s9"}


def test_the_robustness_config_plans_its_120_runs():
    from slamrun.engine.dryrun import dry_run

    spec = load_spec(Path(__file__).parents[1] / "configs" / "robustness.yaml")
    assert {p.kind for p in spec.perturbations} == {"gaussian_noise", "resolution"}
    d = dry_run(spec)
    assert d.total == 120 and d.perturbed_runs == 96


# ------------------------------------------------------------------ perturbations that come and go (schedules)


def test_a_burst_schedule_perturbs_exactly_its_frames_forward_and_backward(room, tmp_path):
    """Bursts of 3 frames every 10 (frames 7-9, 17-19, 27-29 of the sequence): those frames are the static view's,
    every other frame the baseline's, and the backward view holds the same frames in reverse."""
    burst = Perturbation("gaussian_noise", 20.0, schedule="burst:3/10")
    static = prepare(room, FORWARD, Profile.native, tmp_path, perturbation=Perturbation("gaussian_noise", 20.0))
    base = prepare(room, FORWARD, Profile.native, tmp_path)
    fw = prepare(room, FORWARD, Profile.native, tmp_path, perturbation=burst)
    bw = prepare(room, BACKWARD, Profile.native, tmp_path, perturbation=burst)
    n = fw.n_frames
    assert "gaussian_noise-20-burst3of10" in fw.root.name and n == 31
    hit = [i for i in range(n) if not np.array_equal(_frame(fw, i), _frame(base, i))]
    assert hit == [7, 8, 9, 17, 18, 19, 27, 28, 29]
    for i in range(n):
        expected = _frame(static, i) if i in hit else _frame(base, i)
        assert np.array_equal(_frame(fw, i), expected)
        assert np.array_equal(_frame(bw, n - 1 - i), expected)


def test_a_ramp_grows_from_the_ordinary_frame_to_the_level(room, tmp_path):
    """A ramp over the sequence's frames: the first is untouched, the last is the static level's, in between the
    level's share grows (exposure: the gain's log), the same frames backward."""
    ramp = Perturbation("exposure", 0.25, schedule="ramp")
    base = prepare(room, FORWARD, Profile.native, tmp_path)
    fw = prepare(room, FORWARD, Profile.native, tmp_path, perturbation=ramp)
    bw = prepare(room, BACKWARD, Profile.native, tmp_path, perturbation=ramp)
    n = fw.n_frames
    assert np.array_equal(_frame(fw, 0), _frame(base, 0))
    for i in (n // 2, n - 1):
        gain = 0.25 ** (i / (n - 1))
        assert np.abs(_frame(fw, i).astype(float) - np.rint(_frame(base, i) * gain)).max() <= 1
        assert np.array_equal(_frame(bw, n - 1 - i), _frame(fw, i))
    means = [_frame(fw, i).mean() / _frame(base, i).mean() for i in range(n)]
    assert all(a >= b - 1e-3 for a, b in zip(means, means[1:], strict=False))  # ever darker


@pytest.mark.parametrize(
    ("entry", "expected"),
    [
        ({"kind": "resolution", "scale": [0.5], "schedule": "ramp"}, "resolution: a view has one camera"),
        ({"kind": "frame_drop", "every": [2], "schedule": "burst:3/10"}, "frame_drop: a view has one frame rate"),
        ({"kind": "jpeg", "quality": [30], "schedule": "burst:10/5"}, "burst:N/M with 1 <= N < M"),
        ({"kind": "jpeg", "quality": [30], "schedule": "bursts"}, "expected all, burst:N/M or ramp"),
    ],
)
def test_a_wrong_schedule_is_named_before_anything_runs(tmp_path, entry, expected):
    with pytest.raises(SlamRunError) as err:
        load_spec(_spec(tmp_path, perturbations=[entry]))
    assert "perturbations[0]" in str(err.value) and expected in str(err.value)


def test_a_scheduled_perturbation_is_its_own_condition_in_the_plan_and_the_results(tmp_path):
    axis = [
        {"kind": "gaussian_noise", "sigma": [20]},
        {"kind": "gaussian_noise", "sigma": [20], "schedule": "burst:3/10"},
    ]
    runs = plan(load_spec(_spec(tmp_path, perturbations=axis)))
    names = {r.perturbation.name for r in runs}
    assert names == {"none", "gaussian_noise", "gaussian_noise@burst:3/10"}
    keys = {r.key.perturbation for r in runs}
    assert {"gaussian_noise-20", "gaussian_noise-20-burst3of10"} <= keys
    back = Perturbation.named("gaussian_noise@burst:3/10", 20.0, 0)
    assert back == Perturbation("gaussian_noise", 20.0, schedule="burst:3/10")


# ------------------------------------------------------------------ ImageNet-C's corruptions by name


def test_imagenet_c_kinds_are_named_as_the_field_names_them(tmp_path):
    axis = [{"kind": "fog", "severity": [1, 3, 5]}, {"kind": "gaussian_noise", "severity": 3}]
    runs = plan(load_spec(_spec(tmp_path, perturbations=axis)))
    found = {(r.perturbation.kind, r.perturbation.level) for r in runs if not r.perturbation.is_none}
    assert found == {
        ("imagenet_c.fog", 1.0),
        ("imagenet_c.fog", 3.0),
        ("imagenet_c.fog", 5.0),
        ("imagenet_c.gaussian_noise", 3.0),
    }
    assert "imagenet_c.fog-3" in {r.key.perturbation for r in runs}


@pytest.mark.parametrize(
    ("entry", "expected"),
    [
        ({"kind": "fog"}, "fog is ImageNet-C's: give its severities, e.g. {kind: fog, severity: [1, 3, 5]}"),
        ({"kind": "fog", "sigma": [2]}, "fog is ImageNet-C's: give its severities"),
        ({"kind": "exposure", "severity": [2]}, "exposure takes `gain`, not severity"),
        ({"kind": "snow", "severity": [6]}, "snow: severity 6: expected 1 to 5"),
        ({"kind": "snow", "severity": [0]}, "snow: severity 0: the baseline"),
        ({"kind": "gaussian_noise", "severity": [2], "sigma": [3]}, "gaussian_noise takes `severity`, not sigma"),
    ],
)
def test_a_wrong_imagenet_c_entry_is_named_before_anything_runs(tmp_path, entry, expected):
    with pytest.raises(SlamRunError) as err:
        load_spec(_spec(tmp_path, perturbations=[entry]))
    assert "perturbations[0]" in str(err.value) and expected in str(err.value)


@pytest.mark.parametrize("profile", [Profile.native, Profile.rectified])
def test_an_imagenet_c_view_holds_the_corrupted_frames_forward_and_backward(room, tmp_path, profile):
    """Each frame of the view is the ordinary frame corrupted as slamrun.datasets.corruptions says, with the draws
    of its index in the sequence (a rectified view rectifies the corrupted frame); backward the same in reverse."""
    from slamrun.datasets.corruptions import corrupt, draws

    fog = Perturbation("imagenet_c.fog", 3.0)
    fw = prepare(room, FORWARD, profile, tmp_path, perturbation=fog)
    bw = prepare(room, BACKWARD, profile, tmp_path, perturbation=fog)
    n = fw.n_frames
    if profile is Profile.native:
        base = prepare(room, FORWARD, profile, tmp_path)
        for i in (0, 17, n - 1):
            assert np.array_equal(_frame(fw, i), corrupt(_frame(base, i), "fog", 3, draws(0, "room", "fog", 3, i)))
    for i in (0, n // 2, n - 1):
        assert np.array_equal(_frame(fw, i), _frame(bw, n - 1 - i))
    assert not np.array_equal(_frame(fw, 0), _frame(fw, 1))  # each frame its own haze


def test_the_plan_states_what_corrupting_the_frames_costs(tmp_path, capsys):
    """Glass blur's pixel loop is slow (about 0.7 s a 640x480 frame): the plan says the CPU time of the views."""
    from slamrun.cli import main
    from slamrun.datasets.corruptions import SECONDS_PER_MEGAPIXEL
    from slamrun.engine.dryrun import dry_run

    spec = _spec(tmp_path, perturbations=[{"kind": "glass_blur", "severity": [3]}])
    d = dry_run(load_spec(spec))
    one_view = 30 * 160 * 120 / 1e6 * SECONDS_PER_MEGAPIXEL["glass_blur"]  # seq_a: 30 frames of 160x120
    assert d.perturbed_cpu_s == pytest.approx(one_view)  # the backward view links the forward's frames
    assert main(["plan", str(spec)]) == 0
    assert "CPU-minutes to corrupt their frames" in capsys.readouterr().out


def test_imagenet_c_on_frames_under_32_pixels_is_refused_before_anything_runs(tmp_path):
    """The published corruptions are defined on frames of 32 pixels a side or more: a campaign on smaller frames
    was refused by every view's preparation (each run an infrastructure failure); now before it starts."""
    from slamrun.engine.campaign import check_sequences
    from slamrun.errors import DatasetError

    generate(tmp_path / "data" / "tiny", frames=12, seed=1, size=(40, 24))
    spec = {"name": "p", "results": str(tmp_path / "results"), "cache": str(tmp_path / "cache"),
            "datasets": [{"name": "synth", "path": str(tmp_path / "data"), "sequences": ["tiny"]}],
            "methods": [{"name": "reference_vo"}], "perturbations": [{"kind": "fog", "severity": [1]}]}  # fmt: skip
    path = tmp_path / "spec.yaml"
    path.write_text(yaml.safe_dump(spec))
    with pytest.raises(DatasetError, match=r"tiny: ImageNet-C's fog is defined on frames of 32 pixels a side or more"):
        check_sequences(load_spec(path))


def test_fixed_draws_give_every_frame_the_first_frames_random_parts(room, tmp_path):
    """`draws: fixed`: a fog that stays (the first frame's haze on every frame), the same noise pattern; per frame by
    default. A condition of its own (`imagenet_c.fog@fixed`, folders `-fixed`)."""
    from slamrun.datasets.corruptions import corrupt, draws

    fixed = Perturbation("imagenet_c.fog", 3.0, fixed=True)
    base = prepare(room, FORWARD, Profile.native, tmp_path)
    fw = prepare(room, FORWARD, Profile.native, tmp_path, perturbation=fixed)
    bw = prepare(room, BACKWARD, Profile.native, tmp_path, perturbation=fixed)
    assert fw.root.name.split("-imagenet_c.fog-3-fixed-")[0].endswith("native")
    n = fw.n_frames
    for i in (0, 9, n - 1):
        assert np.array_equal(_frame(fw, i), corrupt(_frame(base, i), "fog", 3, draws(0, "room", "fog", 3, 0)))
        assert np.array_equal(_frame(bw, n - 1 - i), _frame(fw, i))
    noise = Perturbation("gaussian_noise", 20.0, fixed=True)
    flat = np.full_like(_frame(base, 5), 128)
    assert np.array_equal(perturb_frame(flat, noise, "room", 3), perturb_frame(flat, noise, "room", 17))
    per_frame = Perturbation("gaussian_noise", 20.0)
    assert not np.array_equal(perturb_frame(flat, per_frame, "room", 3), perturb_frame(flat, per_frame, "room", 17))
    assert Perturbation.named("imagenet_c.fog@burst:3/10@fixed", 3.0) == Perturbation(
        "imagenet_c.fog", 3.0, schedule="burst:3/10", fixed=True
    )


def test_fixed_draws_need_a_random_part(tmp_path):
    with pytest.raises(SlamRunError, match="contrast has no random part: `draws: fixed` changes nothing"):
        load_spec(_spec(tmp_path, perturbations=[{"kind": "contrast", "severity": [2], "draws": "fixed"}]))
    spec = load_spec(_spec(tmp_path, perturbations=[{"kind": "fog", "severity": [2], "draws": "fixed"}]))
    names = {r.perturbation.name for r in plan(spec)}
    assert names == {"none", "imagenet_c.fog@fixed"}
