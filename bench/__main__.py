"""make bench: every figure is measured side by side with its baseline in the same run, then printed with
its target. Speed targets live here, never in the unit tests (machines are noisy). One module per bench."""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

from bench.analysis import bench_analysis
from bench.common import one_core, report
from bench.contention import bench_contention
from bench.datasets import bench_datasets
from bench.demo import bench_demo
from bench.docker import bench_docker
from bench.eta import bench_eta
from bench.evaluate_cores import bench_evaluate_cores
from bench.evaluator import bench_evaluator
from bench.metrics import bench_metrics
from bench.plan import bench_plan_status
from bench.reference_vo import bench_reference_vo
from bench.scale import bench_scale
from bench.scheduler import bench_scheduler
from bench.serve import bench_serve

BENCHES: dict[str, Callable[[Path], None]] = {
    "evaluator": bench_evaluator,
    "evaluate_cores": bench_evaluate_cores,
    "metrics": bench_metrics,
    "scheduler": bench_scheduler,
    "plan": bench_plan_status,
    "datasets": bench_datasets,
    "reference_vo": bench_reference_vo,
    "docker": bench_docker,
    "analysis": bench_analysis,
    "demo": bench_demo,
    "scale": bench_scale,
    "serve": bench_serve,
    "eta": lambda tmp: bench_eta(report),
    "contention": lambda tmp: bench_contention(tmp, report),
}


def main() -> int:
    ap = argparse.ArgumentParser(prog="bench")
    ap.add_argument("--only", nargs="*", choices=list(BENCHES), default=None)
    ap.add_argument("--skip", nargs="*", choices=list(BENCHES), default=[])
    a = ap.parse_args()
    names = [n for n in (a.only or BENCHES) if n not in a.skip]
    for name in names:
        with tempfile.TemporaryDirectory(prefix=f"bench-{name}-") as d:
            pid = os.fork()  # each benchmark in its own process, so CPU pinning does not leak
            if pid == 0:
                if name in ("evaluator", "datasets"):
                    one_core()
                try:
                    BENCHES[name](Path(d))
                    os._exit(0)
                except Exception as exc:  # noqa: BLE001
                    print(f"  {name} failed: {exc!r}", flush=True)
                    os._exit(1)
            os.waitpid(pid, 0)
    return 0


if __name__ == "__main__":
    sys.exit(main())
