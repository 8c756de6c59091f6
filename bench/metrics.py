"""make bench: metrics (one figure set, measured side by side with its baseline)."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from bench.common import report


def bench_metrics(tmp: Path) -> None:
    """1,000 EuRoC-size estimates (1,700 poses at 20 Hz) against a 200 Hz ground truth: `slamrun evaluate
    --metric ate` and `--metric rpe` over all of them as whole processes, against evo_ape and evo_rpe (evo's
    command line, one process per file as it is used) on a sample of the same files, scaled to 1,000."""
    from scipy.spatial.transform import Rotation

    evo_bin = Path(sys.executable).parent
    if not (evo_bin / "evo_ape").exists():
        print("  metrics: skipped (evo's command line is not installed: pip install evo)")
        return
    n_gt, n_est, files, sample = 17000, 1700, 1000, 10
    t_gt = 1403715524.0 + np.arange(n_gt) / 200.0
    phase = np.linspace(0, 4 * np.pi, n_gt)
    gt_pos = np.column_stack([2 * np.cos(phase), np.sin(phase), 1 + 0.2 * np.sin(3 * phase)])
    quat = Rotation.from_euler("zy", np.column_stack([phase, 0.1 * np.sin(phase)])).as_quat()
    np.savetxt(tmp / "gt.txt", np.column_stack([t_gt, gt_pos, quat]), fmt="%.9f")
    rng = np.random.default_rng(0)
    paths = []
    for i in range(files):
        ids = np.arange(0, n_gt, 10)[:n_est]
        est = 0.7 * gt_pos[ids] + rng.normal(scale=0.01, size=(len(ids), 3)) + i * 0.001
        path = tmp / f"est_{i:04d}.txt"
        np.savetxt(path, np.column_stack([t_gt[ids], est, quat[ids]]), fmt="%.9f")
        paths.append(str(path))
    print(f"ATE + RPE: {files} estimates of {n_est} poses against a {n_gt}-row ground truth, whole processes")

    def run(cmd: list[str]) -> float:
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        return time.perf_counter() - t0

    ours = sum(
        run([sys.executable, "-m", "slamrun.cli", "evaluate", "--metric", m, "--gt", str(tmp / "gt.txt"), *paths])
        for m in ("ate", "rpe")
    )
    evo_s = sum(
        run([str(evo_bin / tool), "tum", str(tmp / "gt.txt"), p, "-as", "--t_max_diff", "0.02"])
        for p in paths[:sample]
        for tool in ("evo_ape", "evo_rpe")
    )
    evo_all = evo_s * files / sample
    report(f"slamrun evaluate --metric ate, then rpe ({files} files)", f"{ours:.1f} s", "-")
    report(f"evo_ape + evo_rpe -as, {sample} files, scaled to {files}", f"{evo_all:.1f} s", "-")
    report("  ratio", f"{evo_all / ours:.1f}x", ">= 10x")
