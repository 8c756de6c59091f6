"""DF-ORB-SLAM (834810269/DF-ORB-SLAM @ 462425d): ORB-SLAM2 with LK optical-flow matching and CLAHE.

Upstream has monocular only as a ROS node; the image builds our offline driver `mono_tum_df` (a mono_tum
against its library, no ROS/PCL) and fixes the monocular path, which never fills the optical-flow images (a
run hung at the first motion-model track) nor sizes the flow-tracking vectors (then it crashed). Its pose
optimisation weighs every edge by the keypoint's measured depth, which a monocular frame does not have
(-1): every weight is negative and tracking is lost a few frames after initialisation. `mono_pose: orb`
(the default here) optimises frames without depth with ORB-SLAM2's pose optimisation; `mono_pose: em` keeps
the authors' code. Settings and output as ORB-SLAM2; the adapter's environment (these switches and
ORB_SLAM2_NO_LOOP) is also written into the settings file as `Slamrun.env.NAME: "value"`, which the driver
sets before the system starts unless the variable is already set: the switches hold even when the process
is started without the adapter's environment.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Literal

from pydantic import Field

from slamrun.datasets.view import PreparedView
from slamrun.methods.declare import Source
from slamrun.methods.orb_slam2_family import (
    ORB_VOCABULARY,
    OrbSlam2Family,
    OrbSlam2Params,
    orb_settings_yaml,
    orb_vocabulary,
)


class DfOrbSlamParams(OrbSlam2Params):
    vocabulary: str = Field("/opt/DF-ORB-SLAM/Vocabulary/ORBvoc.txt", description="ORB vocabulary (ORBvoc.txt).")
    mono_pose: Literal["orb", "em"] = Field(
        "orb",
        description="Pose optimisation of frames without depth: ORB-SLAM2's (orb) or the authors' depth-weighted "
        "one (em), whose weights are negative without depth and which loses monocular tracking.",
    )


class DfOrbSlam(OrbSlam2Family):
    sources = (
        Source(
            "df_orb_slam",
            "834810269/DF-ORB-SLAM",
            "462425d61903fa6efc71dde3011cbc3c920c2c16",
            sha256="d071d346217e4e1612cd441f16cfca8eb32cf39f33e68d3bcf3ebe84a61cc8cb",
            tree="e627762c09476849fe5a6d674039716e105898936eacc425f82967ef6911bc6e",
            absent=(ORB_VOCABULARY,),
        ),
    )
    vocabulary = orb_vocabulary("df_orb_slam")
    binary = "/opt/DF-ORB-SLAM/Examples/Monocular/mono_tum_df"
    Params = DfOrbSlamParams
    loop_closure_switch = "env ORB_SLAM2_NO_LOOP=1 (patch in slamrun/methods/df_orb_slam/image)"

    def configure(self, view: PreparedView, workdir: Path) -> dict[str, str]:
        env = {f"Slamrun.env.{k}": json.dumps(v) for k, v in sorted(self.environment().items())}
        return {self.settings_file: orb_settings_yaml(view, self.params, env)}

    def environment(self) -> dict[str, str]:
        env = super().environment()
        return env | ({"DF_ORB_SLAM_MONO_POSE": "orb"} if self.params.mono_pose == "orb" else {})
