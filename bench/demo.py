"""make bench: demo (one figure set, measured side by side with its baseline)."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

from bench.common import ROOT, report

BASELINE_COMMIT = "542f05c"  # before the lanes were kept busy (post-processing on the lane, views prepared first)


def bench_demo(tmp: Path) -> None:
    """The demo campaign, and its lane occupancy against the baseline commit's, side by side on the same data."""
    import sqlite3

    import yaml

    print("the demo campaign (configs/demo.yaml) on generated data: wall time and lane occupancy")
    spec = yaml.safe_load((ROOT / "configs" / "demo.yaml").read_text())
    data = tmp / "data"
    subprocess.run(  # data once, for both
        [sys.executable, "-m", "slamrun.cli", "prepare", str(_demo_spec(tmp, spec, data, "warmup"))],
        check=True,
        capture_output=True,
    )

    def occupancy(code: Path, name: str) -> tuple[float, float, float]:
        path = _demo_spec(tmp, spec, data, name)
        t0 = time.time()
        env = {**os.environ, "PYTHONPATH": str(code)}
        cmd = [sys.executable, "-m", "slamrun.cli", "campaign", str(path), "--no-report"]
        subprocess.run(cmd, check=True, capture_output=True, cwd=code, env=env)
        wall = time.time() - t0
        db = sqlite3.connect(tmp / name / "results" / "ledger.sqlite")
        busy, last = db.execute("SELECT SUM(wall_s), MAX(ended_at) FROM runs WHERE status = 'done'").fetchone()
        db.close()
        return busy / (spec["lanes"] * (last - t0)), busy, wall

    old = tmp / "baseline"
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", BASELINE_COMMIT], capture_output=True)
    if archive.returncode == 0:
        old.mkdir()
        subprocess.run(["tar", "-x", "-C", str(old)], input=archive.stdout, check=True)
        base_occ, base_busy, base_wall = occupancy(old, "old")
        report(f"baseline ({BASELINE_COMMIT}): campaign wall time", f"{base_wall:.0f} s", "-")
        report(f"baseline ({BASELINE_COMMIT}): lane occupancy", f"{100 * base_occ:.1f} %", "-")
    else:
        report(f"baseline ({BASELINE_COMMIT})", "not in this clone", "-")
    occ, busy, wall = occupancy(ROOT, "new")
    report("demo campaign wall time (data prepared)", f"{wall:.0f} s", "< 600 s")
    report("  runs' wall time, summed", f"{busy:.0f} s", "-")
    report("lane occupancy: runs' wall time / (lanes x campaign time)", f"{100 * occ:.1f} %", ">= 95 %")


def _demo_spec(tmp: Path, spec: dict, data: Path, name: str) -> Path:
    """The demo spec with its data, results and view cache in the bench's scratch folder."""
    out = {**spec, "results": str(tmp / name / "results"), "cache": str(tmp / name / "cache"), "report": False}
    out["datasets"] = [{**d, "path": str(data)} for d in spec["datasets"]]
    path = tmp / f"{name}.yaml"
    import yaml

    path.write_text(yaml.safe_dump(out))
    return path
