"""make bench: analysis (one figure set, measured side by side with its baseline)."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from bench.common import report


def bench_analysis(tmp: Path) -> None:
    import pandas as pd

    from slamrun.analysis.report import write_report

    print("analysis: statistics, tables and all figures for a 10,000-run results table")
    rng = np.random.default_rng(0)
    n = 10_000
    methods = [f"method_{i}" for i in range(10)]
    df = pd.DataFrame(
        {
            "method": np.repeat(methods, n // 10),
            "sequence": np.tile(np.repeat([f"sequence_{i:02d}" for i in range(1, 51)], 20), 10),
            "direction": np.tile(np.repeat(["forward", "backward"], 10), 500),
            "trial": np.tile(np.arange(10), 1000),
        }
    )
    scale = np.repeat(np.linspace(0.5, 3, 10), n // 10)
    for m in ("e_t", "e_r", "e_start", "e_end", "e_rmse", "e_align"):
        df[m] = rng.lognormal(np.log(scale), 0.6)
    df["e_s"] = rng.lognormal(0, 0.05 * scale)
    df["e_s_sym"] = np.maximum(df.e_s, 1 / df.e_s)
    failed = rng.random(n) < 0.1
    df.loc[failed, ["e_t", "e_r", "e_s", "e_s_sym", "e_start", "e_end", "e_rmse", "e_align"]] = np.nan
    df["status"] = np.where(failed, "failed", "done")
    df["failure"] = np.where(failed, "lost", None)
    df["eval_status"] = np.where(failed, None, "ok")
    for c, v in (("wall_s", 100), ("fps", 30), ("cpu_mean_pct", 90), ("cpu_peak_pct", 150), ("ram_peak_mb", 400)):
        df[c] = rng.normal(v, v / 10, n)
    df["gpu_mem_peak_mb"] = np.nan
    df["run_dir"] = ""
    df.to_parquet(tmp / "results.parquet")
    t0 = time.perf_counter()
    write_report(tmp)
    report("report: statistics + tables + figures, 10,000 runs", f"{time.perf_counter() - t0:.1f} s", "< 30 s")
