"""DF-ORB-SLAM (834810269/DF-ORB-SLAM @ 462425d): ORB-SLAM2 with LK optical-flow matching and CLAHE.

Upstream has monocular only as a ROS node; the image builds our offline driver `mono_tum_df` (a
mono_tum against its library) and fixes the monocular path that never fills the optical-flow images.
Settings and output as ORB-SLAM2.
"""

from __future__ import annotations

from pydantic import Field

from methods.orb_slam2 import OrbSlam2, OrbSlam2Params


class DfOrbSlamParams(OrbSlam2Params):
    vocabulary: str = Field("/opt/DF-ORB-SLAM/Vocabulary/ORBvoc.txt", description="ORB vocabulary (ORBvoc.txt).")


class DfOrbSlam(OrbSlam2):
    name = "df_orb_slam"
    image = "slamrun/df_orb_slam:latest"
    binary = "/opt/DF-ORB-SLAM/Examples/Monocular/mono_tum_df"
    Params = DfOrbSlamParams
    loop_closure_switch = "env ORB_SLAM2_NO_LOOP=1 (patch in docker/df_orb_slam)"
