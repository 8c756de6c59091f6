"""ORB-SLAM3 v1.0 (UZ-SLAMLab/ORB_SLAM3 @ 4452a3c), monocular, on rectified frames.

`mono_tum VOCAB SETTINGS SEQDIR` reads SEQDIR/rgb.txt. The image's patch (slamrun/methods/orb_slam3/image/patches.py)
turns the
viewer off, fixes upstream's loop-closure switch (the settings' `loopClosing: 0`: no loop closure and no map
merging; keyframes still serve relocalisation) and writes every tracked frame's pose (SaveTrajectoryTUM refuses
monocular) in its working directory: one TUM file per map of the Atlas, `FrameTrajectory.map<ID>.txt` (camera to
world, rgb.txt's timestamps), and last the index `FrameTrajectory.maps.txt` (`map_id frames keyframes` a line).
Frames whose tracking failed have no pose.

ORB-SLAM3 starts a new map when it is lost for good (Atlas). The maps have unrelated frames and scales, so a run
with several maps is never evaluated as one trajectory: by default only the largest map (most frame poses;
the lowest id on a tie) is the run's trajectory, its coverage counts that map's frames only, run.json's
trajectory_report records the number of maps and each map's frames and keyframes, and the run is marked as lost
and relocalised (the `lost` failure when that map cannot be evaluated); `maps: refuse` makes every run with
several maps the failure `lost`, naming its maps.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from pydantic import Field

from slamrun.core.inputs import read_text_bounded
from slamrun.core.trajectory import ReadReport, Trajectory, read_tum
from slamrun.datasets.view import PreparedView, Profile
from slamrun.errors import MethodFailure, SlamRunError, TrajectoryFormatError
from slamrun.methods.declare import Source
from slamrun.methods.orb_slam2_family import (
    ORB_VOCABULARY,
    VIEWER,
    OrbSlam2Params,
    orb_vocabulary,
    pinhole_settings,
)
from slamrun.methods.upstream import UpstreamMethod, fps_of

PREFIX = "FrameTrajectory"
INDEX = f"{PREFIX}.maps.txt"
INDEX_LIMIT = 1 << 20  # bytes: an index line per map; a million bytes is tens of thousands of maps


class OrbSlam3Params(OrbSlam2Params):  # ORB-SLAM2's extractor settings; its own vocabulary; several maps
    vocabulary: str = Field("/opt/ORB_SLAM3/Vocabulary/ORBvoc.txt", description="ORB vocabulary (ORBvoc.txt).")
    n_features: int = Field(2000, ge=100, description="ORBextractor.nFeatures (as ORB-SLAM2 on TUM-Mono: 2000).")
    maps: Literal["largest", "refuse"] = Field(
        "largest",
        description="A run that made several maps: evaluate the largest (marked lost and relocalised, the map "
        "count in run.json), or refuse it as `lost`.",
    )


@dataclass(frozen=True)
class MapsReport(ReadReport):
    """The read report of the evaluated map, with the Atlas's maps: [map id, frames, keyframes] each."""

    n_maps: int = 1
    evaluated_map: int = 0
    maps: list = field(default_factory=list)


def settings_yaml(view: PreparedView, p: OrbSlam3Params) -> str:
    """ORB-SLAM3's settings (File.version 1.0) for a rectified pinhole view: no distortion key, so none is applied.
    ORB-SLAM3 checks each value's type (`must be a real number`): reals are written with a decimal point."""
    reals = {**pinhole_settings(view, "Camera1"), "ORBextractor.scaleFactor": p.scale_factor, **VIEWER}
    integers = {
        "Camera.width": view.width,
        "Camera.height": view.height,
        "Camera.fps": max(1, round(fps_of(view))),
        "Camera.RGB": 0,
        "ORBextractor.nFeatures": p.n_features,
        "ORBextractor.nLevels": p.n_levels,
        "ORBextractor.iniThFAST": p.ini_th_fast,
        "ORBextractor.minThFAST": p.min_th_fast,
        "loopClosing": int(p.loop_closure),
    }
    lines = ["%YAML:1.0", "---", 'File.version: "1.0"', 'Camera.type: "PinHole"']
    lines += [f"{k}: {float(v)!r}" for k, v in reals.items()]
    lines += [f"{k}: {int(v)}" for k, v in integers.items()]
    return "\n".join(lines) + "\n"


def read_index(path: Path) -> list[tuple[int, int, int]]:
    """The maps of FrameTrajectory.maps.txt: (map id, frames, keyframes) per line; MethodFailure naming the file
    and line when it is not that (the writer died half-way, or something else wrote it)."""
    try:
        text = read_text_bounded(path, INDEX_LIMIT, "ORB-SLAM3's map index", SlamRunError)
    except SlamRunError as exc:
        raise MethodFailure("no_output", str(exc)) from None
    maps = []
    for number, line in enumerate(text.splitlines(), 1):
        if not line.strip() or line.startswith("#"):
            continue
        if not re.fullmatch(r"\d{1,18} \d{1,18} \d{1,18}", line.strip()):
            raise MethodFailure(
                "no_output", f"{path.name} line {number}: expected 'map_id frames keyframes', got {line[:60]!r}"
            )
        map_id, frames, keyframes = (int(x) for x in line.split())
        maps.append((map_id, frames, keyframes))
    if len({m[0] for m in maps}) != len(maps):
        raise MethodFailure("no_output", f"{path.name}: a map id is listed twice")
    return maps


def read_maps(workdir: Path) -> tuple[list[tuple[int, int, int]], dict[int, Trajectory]]:
    """Every map's index entry and frame trajectory (TUM, view time); a file whose rows are not the frames its
    index entry states is `no_output`."""
    index = workdir / INDEX
    if not index.exists():
        partial = sorted(p.name for p in workdir.glob(f"{PREFIX}.map*.txt"))
        why = f" (only {', '.join(partial[:3])}: the writer did not finish)" if partial else ""
        raise MethodFailure("no_output", f"ORB-SLAM3 wrote no {INDEX}{why}")
    maps = read_index(index)
    trajectories = {}
    for map_id, frames, _ in maps:
        path = workdir / f"{PREFIX}.map{map_id}.txt"
        if not path.exists():
            raise MethodFailure("no_output", f"{INDEX} lists map {map_id}, but ORB-SLAM3 wrote no {path.name}")
        try:
            traj = read_tum(path)
        except TrajectoryFormatError as exc:
            raise MethodFailure("no_output", f"unreadable output: {exc}") from None
        if traj.report.n_rows != frames:
            raise MethodFailure(
                "no_output", f"{path.name}: {traj.report.n_rows} rows, but {INDEX} states {frames} frames"
            )
        trajectories[map_id] = traj
    return maps, trajectories


def evaluated_map(workdir: Path, refuse: bool) -> Trajectory:
    """The run's trajectory (view time): the only map, or the largest of several (the lowest id on a tie) with a
    MapsReport; MethodFailure `not_initialized` when no frame has a pose, `lost` for several maps when `refuse`."""
    maps, trajectories = read_maps(workdir)
    usable = [m for m in maps if len(trajectories[m[0]])]
    if not usable:
        raise MethodFailure("not_initialized", "ORB-SLAM3 tracked no frame (no map holds a frame pose)")
    described = ", ".join(f"map {i}: {f} frames, {k} keyframes" for i, f, k in maps)
    if len(usable) > 1 and refuse:
        raise MethodFailure("lost", f"ORB-SLAM3 split the run into {len(usable)} maps ({described}); maps: refuse")
    best = max(usable, key=lambda m: (len(trajectories[m[0]]), -m[0]))
    traj = trajectories[best[0]]
    report = MapsReport(**traj.report.__dict__, n_maps=len(usable), evaluated_map=best[0], maps=[list(m) for m in maps])
    return Trajectory(traj.timestamps, traj.positions, traj.quaternions, report=report)


class OrbSlam3(UpstreamMethod):
    threads = 3  # tracking, local mapping and loop closing
    # after the study (shared/upstream README, "Methods after the study"): ORB-SLAM3 v1.0; the stored archive
    # lacks the vocabulary, Examples_old/ and the IMU data folders (one file a line in its .absent.txt)
    sources = (
        Source(
            "orb_slam3",
            "UZ-SLAMLab/ORB_SLAM3",
            "4452a3c4ab75b1cde34e5505a36ec3f9edcdc4c4",
            sha256="b1cdb64a70f5e2443d1db8ced2a2ae3f4980eda237776ddb51e9c511720147ff",
            tree="6654390006ae4d273a344f485958a454790a6b6dbb00a98465424d410a0832bf",
            absent=(
                ORB_VOCABULARY,
                "Examples_old/",
                "Examples/Monocular-Inertial/EuRoC_IMU/",
                "Examples/Monocular-Inertial/TUM_IMU/",
                "Examples/Stereo-Inertial/EuRoC_IMU/",
                "Examples/Stereo-Inertial/TUM_IMU/",
                "evaluation/Ground_truth/EuRoC_imu/",
            ),
        ),
    )
    vocabulary = orb_vocabulary("orb_slam3")  # the same as ORB-SLAM2's
    binary = "/opt/ORB_SLAM3/Examples/Monocular/mono_tum"
    profile = Profile.rectified
    loop_closure_switch = (
        "settings loopClosing: 0 (upstream's switch, fixed by a patch in slamrun/methods/orb_slam3/image)"
    )
    Params = OrbSlam3Params
    output_file = INDEX
    settings_file = "settings.yaml"
    not_initialized_pattern = None  # an index without a pose says it
    # the image's writer names the maps; several maps: lost, then a new map (evaluated_map keeps the largest)
    lost_pattern = r"^slamrun: (?:[2-9]|\d{2,}) map\(s\) with frame poses"

    def configure(self, view: PreparedView, workdir: Path) -> dict[str, str]:
        return {self.settings_file: settings_yaml(view, self.params)}

    def command(self, view: PreparedView, workdir: Path) -> list[str]:
        return [self.exe(), self.params.vocabulary, str(workdir / self.settings_file), str(view.root)]

    def read_trajectory(self, workdir: Path, view: PreparedView) -> Trajectory:
        return view.to_original(evaluated_map(workdir, self.params.maps == "refuse"))

    def accepts_exit(self, exit_code: int, workdir: Path) -> bool:
        """0, or a crash after the index was written (it is written last: the poses are complete)."""
        return exit_code == 0 or (exit_code in (134, 139, -6, -11) and (workdir / INDEX).is_file())
