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
from slamrun.methods.declare import Source, Vocabulary
from slamrun.methods.dso_family import DsoFamily, DsoParams


class LdsoParams(DsoParams):
    vocabulary: str = Field("/opt/LDSO/vocab/orbvoc.dbow3", description="DBoW3 vocabulary shipped with LDSO.")


class Ldso(DsoFamily):
    sources = (
        Source(
            "ldso",
            "tum-vision/LDSO",
            "9b0c48cfd3b3ee95a8dbf1aef2371ed4fca6f81a",
            sha256="b9b39de4a6aa77e50f234ac931912c5e605fe9a0c9f5d5079a02a5d1ff2fd6df",
            tree="af56865268cbc17eb46ad3becdc474ee36f2f8925e7427dc336d77bdebefc5c2",
            absent=("vocab/orbvoc.dbow3",),
        ),
    )
    vocabulary = Vocabulary("ldso", "vocab/orbvoc.dbow3", "dbow3")
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
