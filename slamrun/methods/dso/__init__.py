"""DSO (JakobEngel/dso @ 7b0c99f), on the native view: TUM-Mono's FOV camera.txt with photometric files.

`dso_dataset files=... calib=... gamma=... vignette=... preset=0 mode=0 nogui=1 nolog=1 quiet=1` writes
result.txt (TUM, camera-to-world, marginalised keyframes) in its working directory. DSO finds times.txt
beside `files`. Backward runs use the mirror-time view instead of `reverse=1` (which never processes
frame 0). DSO exits 0 even when it loaded nothing, so an empty result.txt is a failure, not a result.
"""

from __future__ import annotations

from slamrun.methods.declare import Source
from slamrun.methods.dso_family import DsoFamily


class Dso(DsoFamily):
    sources = (
        Source(
            "dso",
            "JakobEngel/dso",
            "7b0c99f01d238f801c625beaff90240bcb007198",
            sha256="4c3266cf9733af6af1cfe91df25fd770ee0f706d5556af46a661a3cea8d7dfca",
            tree="1fcce03d08190b7850738b94b589f0a3d648be75b46863c401bbc1e9beb77d3f",
        ),
    )
    verify_bound = 0.02  # its verification's bound (settled e_align / scene extent), tighter than the default
    binary = "/opt/dso/build/bin/dso_dataset"
