"""The method registry: the one source of truth for method names.

The spec validator, the CLI's method list, the image build targets and the tests all read REGISTRY. Methods from
other Python packages join it through the entry-point group `slamrun.methods` (`name = "package.module:Class"`, a
subclass of methods.base.Method with the same contract as the built-in ones); a plug-in that cannot be loaded is
named with its reason when a spec asks for it (PLUGIN_ERRORS), and never breaks the others.
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
from methods.glomap import Glomap
from methods.ldso import Ldso
from methods.lsd_slam import LsdSlam
from methods.orb_slam2 import OrbSlam2
from methods.orb_slam3 import OrbSlam3
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
        OrbSlam3,
        Glomap,
        External,
    )
}


PLUGIN_GROUP = "slamrun.methods"
PLUGIN_ERRORS: dict[str, str] = {}  # entry-point name -> why it could not be registered
PLUGINS: dict[str, str] = {}  # method name -> the distribution that provides it


def _load_plugins() -> None:
    from importlib.metadata import entry_points

    for ep in entry_points(group=PLUGIN_GROUP):
        where = f"{ep.value} (from {ep.dist.name if ep.dist else 'an unknown distribution'})"
        try:
            cls = ep.load()
        except Exception as exc:  # noqa: BLE001 - any error of someone else's package is reported, not raised
            PLUGIN_ERRORS[ep.name] = f"plug-in {where} cannot be imported: {type(exc).__name__}: {exc}"
            continue
        if not (isinstance(cls, type) and issubclass(cls, Method)):
            PLUGIN_ERRORS[ep.name] = f"plug-in {where} is not a subclass of methods.base.Method"
        elif getattr(cls, "name", None) != ep.name:
            PLUGIN_ERRORS[ep.name] = (
                f"plug-in {where}: its class's name is {getattr(cls, 'name', None)!r}, not {ep.name!r}"
            )
        elif ep.name in REGISTRY:
            PLUGIN_ERRORS[ep.name] = f"plug-in {where}: {ep.name!r} is taken by a built-in method"
        else:
            REGISTRY[ep.name] = cls
            PLUGINS[ep.name] = ep.dist.name if ep.dist else "?"


_load_plugins()


def get(name: str) -> type[Method]:
    try:
        return REGISTRY[name]
    except KeyError:
        if name in PLUGIN_ERRORS:
            raise KeyError(PLUGIN_ERRORS[name]) from None
        raise KeyError(f"unknown method {name!r} (known: {', '.join(sorted(REGISTRY))})") from None
