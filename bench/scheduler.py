"""make bench: scheduler (one figure set, measured side by side with its baseline)."""

from __future__ import annotations

import subprocess
import time
from pathlib import Path

from bench.common import report


def bench_scheduler(tmp: Path) -> None:
    import yaml

    from slamrun.datasets.make_synthetic import generate
    from slamrun.engine.campaign import run_campaign
    from slamrun.engine.spec import DistributedSpec
    from slamrun.engine.spec_file import load_spec

    print("scheduler: per-run overhead with a no-op method, against a bare spawn of the same command")
    generate(tmp / "data" / "s", frames=30, seed=0, size=(64, 48))
    n = 60
    spec = {
        "name": "b",
        "results": str(tmp / "res"),
        "cache": str(tmp / "cache"),
        "datasets": [{"name": "d", "path": str(tmp / "data"), "sequences": ["s"]}],
        "methods": [{"name": "external", "params": {"argv": ["/bin/true"]}}],
        "directions": ["forward"],
        "trials": n,
        "lanes": 1,
        "report": False,
        "evaluate": False,
    }
    (tmp / "b.yaml").write_text(yaml.safe_dump(spec))
    loaded = load_spec(tmp / "b.yaml")
    run_campaign(loaded.model_copy(update={"trials": 1}), log=lambda *a: None)  # warm: cache, imports
    t0 = time.perf_counter()
    run_campaign(loaded, log=lambda *a: None)
    campaign_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    for _ in range(n):
        subprocess.run(["/bin/true"], check=False)
    bare_s = time.perf_counter() - t0
    overhead_ms = (campaign_s - bare_s) / n * 1000
    report("campaign, per run (no-op method)", f"{campaign_s / n * 1000:.1f} ms", "-")
    report("bare subprocess.run, per run", f"{bare_s / n * 1000:.1f} ms", "-")
    report("scheduler overhead per run", f"{overhead_ms:.1f} ms", "< 50 ms")
    # runs of 1 s on 2 lanes: the share of the lanes' time the runs use (status's occupancy)
    from slamrun.engine.session import read_figures

    busy_spec = loaded.model_copy(
        update={
            "results": tmp / "res-busy",
            "lanes": 2,
            "trials": 40,
            "methods": [loaded.methods[0].model_copy(update={"params": {"argv": ["/bin/sleep", "1"]}})],
        }
    )
    run_campaign(busy_spec, log=lambda *a: None)
    f = read_figures(tmp / "res-busy")
    busy = (f.occupancy or 0.0) if f else 0.0
    report("lanes busy, 40 runs of 1 s on 2 lanes", f"{100 * busy:.1f} %", ">= 90 %")
    try:
        import distributed  # noqa: F401
    except ImportError:
        return
    dask_spec = loaded.model_copy(
        update={"results": tmp / "res-dask", "distributed": DistributedSpec(address="local"), "lanes": 1}
    )
    t0 = time.perf_counter()
    run_campaign(dask_spec.model_copy(update={"trials": 1}), log=lambda *a: None)
    startup_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    run_campaign(dask_spec, log=lambda *a: None)
    dask_s = time.perf_counter() - t0
    report("Dask engine (1 local worker): cluster start + 1 run", f"{startup_s:.1f} s", "-")
    report("Dask engine: per run, cluster start spread over the runs", f"{dask_s / n * 1000:.1f} ms", "-")
    report("  extra per run over the local lanes", f"{(dask_s - campaign_s) / n * 1000:.1f} ms", "-")
