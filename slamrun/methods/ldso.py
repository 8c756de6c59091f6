"""LDSO (tum-vision/LDSO @ 9b0c48c): DSO with loop closure, on the native view.

`run_dso_tum_mono files= calib= gamma= vignette= preset=0 mode=0 nogui=1 nolog=1 quiet=1 loopclosing=0
output=FILE vocab=FILE` writes FILE (pose-graph corrected) and FILE.noloop (TUM, camera-to-world, every
keyframe). It loads the vocabulary even with loopclosing=0 (and aborts without one). Upstream segfaults at
exit with nogui=1 after writing (a null viewer); the image patches that, and exit 139 is still accepted
when the output is complete, for images built otherwise.
"""

from __future__ import annotations

from pathlib import Path

from pydantic import Field

from slamrun.datasets.view import PreparedView
from slamrun.methods.dso import Dso, DsoParams


class LdsoParams(DsoParams):
    vocabulary: str = Field("/opt/LDSO/vocab/orbvoc.dbow3", description="DBoW3 vocabulary shipped with LDSO.")


class Ldso(Dso):
    name = "ldso"
    image = "slamrun/ldso:latest"
    binary = "/opt/LDSO/bin/run_dso_tum_mono"
    Params = LdsoParams
    loop_closure_switch = "loopclosing=0"
    output_file = "result.txt"

    def command(self, view: PreparedView, workdir: Path) -> list[str]:
        p = self.params
        return [
            self.exe(),
            *self.dataset_args(view),
            "mode=0" if self.photometric(view) else "mode=1",
            "nolog=1",
            "quiet=1",
            f"loopclosing={int(p.loop_closure)}",
            f"output={workdir / self.output_file}",
            f"vocab={p.vocabulary}",
        ]

    def accepts_exit(self, exit_code: int, workdir: Path) -> bool:
        if exit_code == 0:
            return True
        # the null-viewer segfault after the results were written
        out = workdir / self.output_file
        return exit_code in (139, -11) and out.exists() and out.stat().st_size > 0
