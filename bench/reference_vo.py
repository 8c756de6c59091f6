"""make bench: reference_vo (one figure set, measured side by side with its baseline)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from bench.common import report


def bench_reference_vo(tmp: Path) -> None:
    from slamrun.datasets.cache import prepare
    from slamrun.datasets.make_synthetic import generate
    from slamrun.datasets.view import Direction, Profile

    print("reference VO at 640x480 (one core)")
    seq = generate(tmp / "vo" / "s", frames=300, seed=0)
    view = prepare(seq, Direction.forward, Profile.rectified, tmp / "cache")
    out = subprocess.run(
        [
            "taskset",
            "-c",
            str(sorted(os.sched_getaffinity(0))[0]),
            sys.executable,
            "-m",
            "slamrun.methods.reference_vo",
            "--images",
            str(view.path(view.images_dir)),
            "--times",
            str(view.path(view.times)),
            "--camera",
            str(view.path(view.camera)),
            "--out",
            str(tmp / "vo.txt"),
        ],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    last = out.strip().splitlines()[-1].split(",")
    processing, total = (float(part.split()[0]) for part in last[-2:])
    report("reference VO, processing (tracking, mapping, BA)", f"{processing:.1f} fps", ">= 30 fps")
    report("reference VO, with PNG decoding of the frames", f"{total:.1f} fps", "-")
