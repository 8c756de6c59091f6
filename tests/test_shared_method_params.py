"""What methods of one family declare once: the seed every trial gets its own of (colmap, glomap, DPVO,
DROID-SLAM), a native GPU method's network and build folder, ORB-SLAM2's extractor settings that ORB-SLAM3 keeps,
the ORB vocabulary the family's archives lack, and the settings files' camera and viewer keys."""

from __future__ import annotations

from pathlib import Path

import pytest

import slamrun.methods
from slamrun.datasets.view import Direction, PreparedView, Profile
from slamrun.methods.declare import Vocabulary, declared
from slamrun.methods.orb_slam2_family import OrbSlam2Params, orb_settings_yaml
from slamrun.methods.orb_slam3 import OrbSlam3Params, settings_yaml

PER_TRIAL = "default: one per trial, from the trial and the campaign's seed"
SEEDS = {
    "colmap": f"Mapper random seed; {PER_TRIAL} (a fixed value makes every trial the same: identical runs).",
    "glomap": f"Random seed of the global mapper; {PER_TRIAL} (a fixed value makes every trial the same: identical "
    "runs).",
    "dpvo": f"Seed of PyTorch's generators; {PER_TRIAL} (a fixed value makes every trial the same seed; the GPU's own "
    "order still varies).",
}
SEEDS["droid_slam"] = SEEDS["mast3r_slam"] = SEEDS["dpvo"]


@pytest.mark.parametrize("name", sorted(SEEDS))
def test_the_seed_parameter_says_each_trial_gets_its_own(name):
    cls = slamrun.methods.get(name)
    seed = cls.Params.model_fields["seed"]
    assert cls.seed_param == "seed" and seed.default is None and seed.description == SEEDS[name]
    assert list(cls.Params.model_fields)[-1] == "seed"  # declared last, as before


@pytest.mark.parametrize(
    "name, network",
    [("dpvo", "dpvo.pth"), ("droid_slam", "droid.pth"),
     ("mast3r_slam", "MASt3R_ViTLarge_BaseDecoder_512_catmlpdpt_metric.pth")],
)  # fmt: skip
def test_a_native_gpu_method_names_its_network_and_build_folder(name, network):
    fields = slamrun.methods.get(name).Params.model_fields
    assert list(fields)[:2] == ["weights", "build"]
    assert fields["weights"].default is None and fields["build"].default is None
    assert fields["weights"].description == (
        f"The network ({network}); default: the one the native build (or the image) holds."
    )
    assert (
        fields["build"].description
        == f"Folder of a native build (default: where `slamrun native-build {name}` puts it)."
    )


def test_orb_slam3_keeps_orb_slam2s_extractor_settings_in_their_order():
    assert list(OrbSlam3Params.model_fields) == [*OrbSlam2Params.model_fields, "maps"]
    p2, p3 = OrbSlam2Params(), OrbSlam3Params()
    assert p3.vocabulary == "/opt/ORB_SLAM3/Vocabulary/ORBvoc.txt" != p2.vocabulary
    assert p3.model_dump(exclude={"vocabulary", "maps"}) == p2.model_dump(exclude={"vocabulary"})
    described = OrbSlam3Params.model_fields["n_features"].description
    assert described == "ORBextractor.nFeatures (as ORB-SLAM2 on TUM-Mono: 2000)."
    assert OrbSlam2Params.model_fields["n_features"].description == "ORBextractor.nFeatures (TUM-Mono: 2000)."


@pytest.mark.parametrize("name", ["orb_slam2", "df_orb_slam", "dynaslam", "orb_slam3"])
def test_the_orb_family_declares_the_vocabulary_its_archive_lacks(name):
    cls = slamrun.methods.get(name)
    assert declared(cls, "vocabulary") == Vocabulary(name, "Vocabulary/ORBvoc.txt.tar.gz", "dbow2-text")
    (source,) = declared(cls, "sources")
    assert source.name == name and source.absent[0] == "Vocabulary/ORBvoc.txt.tar.gz"


def _view(root: Path) -> PreparedView:
    (root / "times.txt").write_text("".join(f"{i:06d} {i / 30:.6f} 1.0\n" for i in range(31)))
    return PreparedView(
        root, "s", Direction.forward, Profile.rectified, 31, 0.0, 1.0, 640, 480, (320.5, 320.0, 319.5, 239.5)
    )


VIEWER_2 = [
    "Viewer.KeyFrameSize: 0.05",
    "Viewer.KeyFrameLineWidth: 1",
    "Viewer.GraphLineWidth: 0.9",
    "Viewer.PointSize: 2",
    "Viewer.CameraSize: 0.08",
    "Viewer.CameraLineWidth: 3",
    "Viewer.ViewpointX: 0",
    "Viewer.ViewpointY: -0.7",
    "Viewer.ViewpointZ: -1.8",
    "Viewer.ViewpointF: 500",
]


def test_orb_slam2s_settings_as_written_before(tmp_path):
    text = orb_settings_yaml(_view(tmp_path), OrbSlam2Params(), {"Slamrun.env.X": '"1"'})
    camera = ["Camera.fx: 320.5", "Camera.fy: 320.0", "Camera.cx: 319.5", "Camera.cy: 239.5"]
    zeros = [f"Camera.{k}: 0.0" for k in ("k1", "k2", "p1", "p2", "k3")]
    sizes = ["Camera.width: 640", "Camera.height: 480", "Camera.fps: 30.0", "Camera.RGB: 0"]
    orb = [
        "ORBextractor.nFeatures: 2000",
        "ORBextractor.scaleFactor: 1.2",
        "ORBextractor.nLevels: 8",
        "ORBextractor.iniThFAST: 20",
        "ORBextractor.minThFAST: 7",
    ]
    lines = ["%YAML:1.0", "---", *camera, *zeros, *sizes, *orb, *VIEWER_2, 'Slamrun.env.X: "1"']
    assert text == "\n".join(lines) + "\n"


def test_orb_slam3s_settings_write_reals_with_a_decimal_point(tmp_path):
    text = settings_yaml(_view(tmp_path), OrbSlam3Params())
    head = ["%YAML:1.0", "---", 'File.version: "1.0"', 'Camera.type: "PinHole"']
    camera = ["Camera1.fx: 320.5", "Camera1.fy: 320.0", "Camera1.cx: 319.5", "Camera1.cy: 239.5"]
    viewer = [line if "." in line.split(": ")[1] else line + ".0" for line in VIEWER_2]
    integers = [
        "Camera.width: 640",
        "Camera.height: 480",
        "Camera.fps: 30",
        "Camera.RGB: 0",
        "ORBextractor.nFeatures: 2000",
        "ORBextractor.nLevels: 8",
        "ORBextractor.iniThFAST: 20",
        "ORBextractor.minThFAST: 7",
        "loopClosing: 0",
    ]
    lines = [*head, *camera, "ORBextractor.scaleFactor: 1.2", *viewer, *integers]
    assert text == "\n".join(lines) + "\n"
