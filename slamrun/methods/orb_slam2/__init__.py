"""ORB-SLAM2 (raulmur/ORB_SLAM2 @ f2e6f51), monocular, on rectified frames.

`mono_tum VOCAB SETTINGS SEQDIR` reads SEQDIR/rgb.txt and writes KeyFrameTrajectory.txt (TUM, keyframes,
camera-to-world) in its working directory. The image's patch adds a loop-closure switch (the environment
variable ORB_SLAM2_NO_LOOP=1) and turns the viewer off.
"""

from __future__ import annotations

from slamrun.methods.declare import Source
from slamrun.methods.orb_slam2_family import ORB_VOCABULARY, OrbSlam2Family, orb_vocabulary


class OrbSlam2(OrbSlam2Family):
    sources = (
        Source(
            "orb_slam2",
            "raulmur/ORB_SLAM2",
            "f2e6f51cdc8d067655d90a78c06261378e07e8f3",
            sha256="9470620833e1e57aff2aec40a5e90a8c4f55f4bbb7da218dbe234210db320404",
            tree="de0da80496099c3ec5f1c14e9bc64382734ec86d1c6b20b7784d48612106e7f1",
            absent=(ORB_VOCABULARY,),
        ),
    )
    vocabulary = orb_vocabulary("orb_slam2")
    binary = "/opt/ORB_SLAM2/Examples/Monocular/mono_tum"
    loop_closure_switch = "env ORB_SLAM2_NO_LOOP=1 (patch in slamrun/methods/orb_slam2/image)"
