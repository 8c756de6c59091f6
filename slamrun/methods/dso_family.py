"""DSO's family (DSO, LDSO, CNN-DSO): DSO's parameters and the adapter of its `dso_dataset`-style command line on the
native view (TUM-Mono's FOV camera.txt, with photometric files where the dataset has them). Each member's folder
declares its own name, image, sources and binary."""

from __future__ import annotations

from pathlib import Path

from pydantic import Field

from slamrun.datasets.view import PreparedView, Profile
from slamrun.methods.upstream import UpstreamMethod, UpstreamParams


class DsoParams(UpstreamParams):
    preset: int = Field(0, ge=0, le=3, description="0: not real-time, all frames (the benchmark's setting).")
    photometric: bool = Field(True, description="mode=0 with pcalib and vignette; false: mode=1 (none).")
    single_thread: bool = Field(False, description="nomt=1: repeatable runs, slower.")


class DsoFamily(UpstreamMethod):
    """The adapter DSO's family shares: DSO's arguments, its output, its failure patterns."""

    threads = 2  # tracking and mapping (nomt=1: one)
    profile = Profile.native
    loop_closure_switch = None  # DSO has no loop closure
    Params = DsoParams
    output_file = "result.txt"
    not_initialized_pattern = r"INITIALIZATION FAILED|no images loaded|could not load"
    lost_pattern = r"^LOST"

    def dataset_args(self, view: PreparedView) -> list[str]:
        """The sequence and calibration arguments DSO's family share: files, calib, preset, photometric files."""
        p = self.params
        argv = [
            f"files={view.path(view.images_dir)}",
            f"calib={view.path(view.camera)}",
            f"preset={p.preset}",
            "nogui=1",
        ]
        if self.photometric(view):
            argv += [f"gamma={view.path(view.pcalib)}", f"vignette={view.path(view.vignette)}"]
        return argv

    def photometric(self, view: PreparedView) -> bool:
        """mode=0 with the view's photometric calibration when asked for and the dataset has one (TUM-Mono);
        mode=1 otherwise (EuRoC, KITTI, TUM RGB-D, TUM-VI carry none)."""
        return self.params.photometric and view.photometric

    def busy_threads(self) -> int:
        return 1 if self.params.single_thread else 2  # tracking and mapping; nomt=1: one thread

    def command(self, view: PreparedView, workdir: Path) -> list[str]:
        p = self.params
        mode = "mode=0" if self.photometric(view) else "mode=1"
        argv = [self.exe(), *self.dataset_args(view), "nolog=1", "quiet=1", mode]
        if p.single_thread:
            argv.append("nomt=1")
        return argv + self.extra_args(view, workdir)

    def extra_args(self, view: PreparedView, workdir: Path) -> list[str]:
        return []
