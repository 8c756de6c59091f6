"""The method registry: the one source of truth for method names.

The spec validator, the CLI's method list, the image build targets and the tests all read REGISTRY.
"""

from __future__ import annotations

from methods.base import Method
from methods.cnn_dso import CnnDso
from methods.cnn_svo import CnnSvo
from methods.colmap import Colmap
from methods.df_orb_slam import DfOrbSlam
from methods.dsm import Dsm
from methods.dso import Dso
from methods.dynaslam import DynaSlam
from methods.external import External
from methods.ldso import Ldso
from methods.lsd_slam import LsdSlam
from methods.orb_slam2 import OrbSlam2
from methods.reference_vo.adapter import ReferenceVO
from methods.svo import Svo

STUDY_METHODS = ("orb_slam2", "df_orb_slam", "lsd_slam", "dso", "svo", "ldso", "dsm", "dynaslam", "cnn_dso", "cnn_svo")

REGISTRY: dict[str, type[Method]] = {
    cls.name: cls
    for cls in (
        OrbSlam2,
        DfOrbSlam,
        LsdSlam,
        Dso,
        Svo,
        Ldso,
        Dsm,
        DynaSlam,
        CnnDso,
        CnnSvo,
        ReferenceVO,
        Colmap,
        External,
    )
}


def get(name: str) -> type[Method]:
    try:
        return REGISTRY[name]
    except KeyError:
        raise KeyError(f"unknown method {name!r} (known: {', '.join(sorted(REGISTRY))})") from None
