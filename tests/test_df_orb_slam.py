"""DF-ORB-SLAM's switches reach the process through the settings file too: the adapter writes its environment
there (`Slamrun.env.NAME: "value"`) and the driver mono_tum_df sets each variable before the system starts,
unless it is already set."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import cv2
import numpy as np
import pytest

import slamrun.methods
from slamrun.datasets.view import Direction, PreparedView, Profile
from tests.conftest import recipe

ROOT = Path(__file__).resolve().parents[1]
DRIVER = recipe("df_orb_slam") / "mono_tum_df.cc"


def _view(root: Path) -> PreparedView:
    root.mkdir(parents=True, exist_ok=True)
    t = 1000.0 + np.arange(10) / 30.0
    return PreparedView(
        root, "seq", Direction.forward, Profile.rectified, len(t), t[0], t[-1], 640, 480, (320.0, 320.0, 319.5, 239.5)
    )


def _settings_env(tmp_path: Path, **params) -> dict[str, str]:
    m = slamrun.methods.get("df_orb_slam")(params)
    path = tmp_path / "settings.yaml"
    path.write_text(m.configure(_view(tmp_path / "view"), Path("/work"))["settings.yaml"])
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    assert fs.isOpened() and fs.getNode("Camera.fx").real() == 320.0
    root = fs.root()
    return {k[len("Slamrun.env.") :]: root.getNode(k).string() for k in root.keys() if k.startswith("Slamrun.env.")}


def test_df_orb_slam_settings_carry_the_adapter_environment(tmp_path):
    m = slamrun.methods.get("df_orb_slam")({})
    assert _settings_env(tmp_path) == m.environment() == {"ORB_SLAM2_NO_LOOP": "1", "DF_ORB_SLAM_MONO_POSE": "orb"}
    assert _settings_env(tmp_path, mono_pose="em", loop_closure=True) == {}


OPENCV_CORE = Path("/usr/include/opencv4/opencv2/core.hpp")  # Debian's libopencv-core-dev (.ci/run installs it)


@pytest.mark.skipif(
    not shutil.which("g++") or not OPENCV_CORE.is_file(),
    reason="needs g++ and OpenCV 4's core headers (apt-get install libopencv-core-dev; .ci/run installs it)",
)
def test_df_orb_slam_driver_sets_the_environment_from_the_settings(tmp_path):
    """The driver's ApplySettingsEnvironment, compiled on the host with a main that prints the variables."""
    src = DRIVER.read_text()
    fn = src[src.index("static void ApplySettingsEnvironment") : src.index("int main(")]
    (tmp_path / "t.cc").write_text(
        "#include <cstdlib>\n#include <iostream>\n#include <string>\n#include <opencv2/core/core.hpp>\n"
        + fn
        + "int main(int, char **argv)\n{\n    ApplySettingsEnvironment(argv[1]);\n"
        '    for (const char *n : {"DF_ORB_SLAM_MONO_POSE", "ORB_SLAM2_NO_LOOP"})\n'
        '        std::cout << "got " << n << "=" << (getenv(n) ? getenv(n) : "-") << std::endl;\n}\n'
    )
    flags = [f"-I{OPENCV_CORE.parents[1]}", "-lopencv_core"]  # the function uses cv::FileStorage only
    subprocess.run(["g++", "-std=c++14", str(tmp_path / "t.cc"), "-o", str(tmp_path / "t"), *flags], check=True)
    settings = tmp_path / "settings.yaml"
    settings.write_text(
        slamrun.methods.get("df_orb_slam")({}).configure(_view(tmp_path / "view"), Path("/work"))["settings.yaml"]
    )

    def run(**env):
        base = {"PATH": "/usr/bin:/bin"}
        out = subprocess.run([str(tmp_path / "t"), str(settings)], capture_output=True, text=True, env=base | env)
        assert out.returncode == 0, out.stderr
        return [line for line in out.stdout.splitlines() if line.startswith("got ")]

    assert run() == ["got DF_ORB_SLAM_MONO_POSE=orb", "got ORB_SLAM2_NO_LOOP=1"]
    # a variable already set wins over the settings file
    assert run(DF_ORB_SLAM_MONO_POSE="em") == ["got DF_ORB_SLAM_MONO_POSE=em", "got ORB_SLAM2_NO_LOOP=1"]
