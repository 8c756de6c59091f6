"""make bench: metrics (one figure set, measured side by side with its baseline)."""

from __future__ import annotations

import resource
import statistics
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
    bench_large_file(tmp, evo_bin)


def bench_large_file(tmp: Path, evo_bin: Path) -> None:
    """One 100,000-pose estimate (200 Hz, 500 s) against its ground truth: ATE and RPE in one `slamrun evaluate`
    process (its defaults for a TUM file: Sim(3), RPE over 1 s) against evo_ape + evo_rpe -as (every consecutive
    pair: as many pairs), in CPU time (user + system of each process), the median of three side by side."""
    from scipy.spatial.transform import Rotation

    n = 100_000
    t = 1403715524.0 + np.arange(n) / 200.0
    phase = np.linspace(0, 40 * np.pi, n)
    pos = np.column_stack([2 * np.cos(phase), np.sin(phase), 1 + 0.2 * np.sin(3 * phase)])
    quat = Rotation.from_euler("zy", np.column_stack([phase, 0.1 * np.sin(phase)])).as_quat()
    gt, est = tmp / "gt_100k.txt", tmp / "est_100k.txt"
    np.savetxt(gt, np.column_stack([t, pos, quat]), fmt="%.9f")
    noisy = 0.7 * pos + np.random.default_rng(1).normal(scale=0.01, size=pos.shape)
    np.savetxt(est, np.column_stack([t, noisy, quat]), fmt="%.9f")
    ours, evo = [], []
    for _ in range(3):
        ours.append(cpu_seconds([sys.executable, "-m", "slamrun.cli", "evaluate", "--gt", str(gt), str(est)]))
        evo.append(
            sum(cpu_seconds([str(evo_bin / tool), "tum", str(gt), str(est), "-as"]) for tool in ("evo_ape", "evo_rpe"))
        )
    print(f"ATE + RPE of one {n:,}-pose estimate, CPU time of whole processes (median of 3)")
    report("slamrun evaluate (ATE and RPE, one process)", f"{statistics.median(ours):.2f} s CPU", "-")
    report("evo_ape + evo_rpe -as", f"{statistics.median(evo):.2f} s CPU", "-")
    report("  ratio", f"{statistics.median(evo) / statistics.median(ours):.1f}x", ">= 10x")


def cpu_seconds(cmd: list[str]) -> float:
    """The user + system CPU seconds of `cmd` and its children, run to its end."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
