"""make bench: docker (one figure set, measured side by side with its baseline)."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

from bench.common import report


def bench_docker(tmp: Path) -> None:
    import threading

    import psutil

    from slamrun.backends.base import ExecRequest
    from slamrun.backends.docker import DockerBackend
    from slamrun.backends.monitor import ProcessTreeMonitor
    from slamrun.datasets.cache import prepare
    from slamrun.datasets.make_synthetic import generate
    from slamrun.datasets.view import Direction, Profile
    from slamrun.errors import InfraError

    print("docker backend: per-run overhead against `docker run --rm` of the same no-op image; monitor cost")
    backend = DockerBackend()
    try:
        backend.check({"reference_vo": "slamrun/reference_vo:latest"})
    except InfraError as exc:
        report("docker backend", "skipped", str(exc)[:60])
        return
    seq = generate(tmp / "d" / "s", frames=30, seed=0, size=(64, 48))
    view = prepare(seq, Direction.forward, Profile.native, tmp / "cache")
    n = 10
    t0 = time.perf_counter()
    for i in range(n):
        work = tmp / f"w{i}"
        work.mkdir()
        req = ExecRequest(
            argv=["true"],
            workdir=work,
            view=view,
            log_path=tmp / f"log{i}",
            image="slamrun/reference_vo:latest",
            resources_path=tmp / f"res{i}.csv",
            timeout_s=60,
        )
        backend.execute(req, threading.Event())
    ours = (time.perf_counter() - t0) / n
    t0 = time.perf_counter()
    for _ in range(n):
        subprocess.run(
            [
                "docker",
                "run",
                "--rm",
                "--network",
                "none",
                "-v",
                f"{view.root}:/data:ro",
                "slamrun/reference_vo:latest",
                "true",
            ],
            check=True,
            capture_output=True,
        )
    bare = (time.perf_counter() - t0) / n
    report("DockerBackend.execute, no-op container", f"{ours * 1000:.0f} ms", "-")
    report("docker run --rm, same image and mount", f"{bare * 1000:.0f} ms", "-")
    report("ratio backend / docker run", f"{ours / bare:.2f}", "<= 1.2")

    # the monitor's own CPU at 2 Hz, sampling a busy process tree for 10 s
    busy = subprocess.Popen([sys.executable, "-c", "import time\nend=time.time()+10\nwhile time.time()<end: pass"])
    me = psutil.Process()
    c0 = sum(me.cpu_times()[:2])
    mon = ProcessTreeMonitor(busy.pid, 0.5).start()
    busy.wait()
    mon.stop()
    cost = (sum(me.cpu_times()[:2]) - c0) / 10 * 100
    report("process-tree monitor at 2 Hz, CPU of one core", f"{cost:.2f} %", "< 2 %")
