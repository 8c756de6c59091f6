"""make bench: plan (one figure set, measured side by side with its baseline)."""

from __future__ import annotations

import time
from pathlib import Path

from bench.common import report


def bench_plan_status(tmp: Path) -> None:
    from slamrun.analysis.summary import method_summary
    from slamrun.engine.export import results_frame
    from slamrun.engine.ledger import Ledger
    from slamrun.engine.plan import plan
    from slamrun.engine.spec_file import validate_spec

    print("plan and status of a 10,000-run campaign")
    raw = {
        "name": "big",
        "results": str(tmp / "big"),
        "trials": 10,
        "datasets": [
            {"name": "tum", "path": str(tmp / "nowhere"), "sequences": [f"sequence_{i:02d}" for i in range(1, 51)]}
        ],
        "methods": [{"name": "external", "label": f"m{i}", "params": {"argv": ["true", str(i)]}} for i in range(10)],
    }
    t0 = time.perf_counter()
    spec = validate_spec(raw, base_dir=tmp, check_files=False)
    runs = plan(spec)
    ledger = Ledger(tmp / "big" / "ledger.sqlite")
    ledger.sync_plan(runs)
    plan_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    df = results_frame(ledger)
    method_summary(df)
    ledger.counts()
    status_s = time.perf_counter() - t0
    assert len(runs) == 10_000 and len(df) == 10_000
    report("plan 10,000 runs and write them to the ledger", f"{plan_s:.2f} s", "< 2 s")
    report("load the status of 10,000 runs", f"{status_s:.2f} s", "< 2 s")
