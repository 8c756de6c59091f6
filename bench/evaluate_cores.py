"""make bench: evaluate_cores (one figure set, measured side by side with its baseline)."""

from __future__ import annotations

import math
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from bench.common import ROOT, report


def bench_evaluate_cores(tmp: Path) -> None:
    from scipy.spatial.transform import Rotation

    from slamrun.core.batch_eval import evaluate_files
    from slamrun.core.trajectory import Trajectory

    jobs = len(os.sched_getaffinity(0))
    print(f"slamrun evaluate on every core ({jobs}) against one core: 1,000 trajectories of 2,206 poses")
    n = 2206  # the measurement: real-format files of sequence length
    t = 1400000000.0 + np.arange(n) / 22.0
    phase = np.linspace(0, 2 * np.pi, n)
    pos = np.column_stack([np.cos(phase), np.sin(phase), 0.1 * phase])
    quat = Rotation.from_euler("z", phase[:, None]).as_quat()
    gt_pos = pos.copy()
    gt_pos[int(0.15 * n) : int(0.85 * n)] = np.nan
    data = np.column_stack([t, gt_pos, quat])
    gt = Trajectory(data[:, 0], data[:, 1:4], data[:, 4:8])
    rng = np.random.default_rng(0)
    files = []
    for i in range(1000):
        est = 0.5 * pos + rng.normal(scale=0.01, size=pos.shape) + i * 0.001
        path = tmp / f"est_{i}.txt"
        np.savetxt(path, np.column_stack([t, est, quat]), fmt="%.15g")  # DSO writes 15 significant digits
        files.append(path)

    def seconds(j: int) -> float:
        best = math.inf
        for _ in range(2):
            t0 = time.perf_counter()
            assert sum(d["status"] == "ok" for d in evaluate_files(gt, files, jobs=j)) == len(files)
            best = min(best, time.perf_counter() - t0)
        return best

    one, every = seconds(1), seconds(jobs)
    report("slamrun evaluate, one core (1,000 files)", f"{one:.2f} s", "-")
    report(f"slamrun evaluate, {jobs} cores (--jobs default)", f"{every:.2f} s", "-")
    report("  speed-up over one core", f"{one / every:.2f}x", "-")
    # whole processes on the same files: `slamrun evaluate` and the official MATLAB code under Octave
    gt_path = tmp / "groundtruthSync.txt"
    np.savetxt(gt_path, data, fmt="%.9f")
    slamrun = str(Path(sys.executable).parent / "slamrun")
    times = []
    for _ in range(3):  # a 0.4 s process: its median of three (the official one takes a minute, run once)
        t0 = time.perf_counter()
        subprocess.run([slamrun, "evaluate", "--gt", str(gt_path), *map(str, files)], check=True, capture_output=True)
        times.append(time.perf_counter() - t0)
    ours_process = statistics.median(times)
    spread = f"{min(times):.2f}-{max(times):.2f}"
    report("slamrun evaluate as a process (1,000 files, every core)", f"{ours_process:.2f} s ({spread})", "-")
    from bench import official

    if official.octave() is None:
        report("official evaluator (Octave)", "skipped: GNU Octave not installed", "apt-get install octave")
        return
    upstream = ROOT.parent / "shared" / "upstream"
    folder = official.evaluator_dir(tmp / "official", upstream if upstream.is_dir() else None)
    argv, _ = official.command(folder, gt_path, files, tmp)
    t0 = time.perf_counter()
    subprocess.run(argv, cwd=folder, check=True, capture_output=True)
    theirs = time.perf_counter() - t0
    report("official TUM-Mono evaluator under Octave, same 1,000 files", f"{theirs:.1f} s", "-")
    report("  ratio official / slamrun evaluate (whole processes)", f"{theirs / ours_process:.1f}x", ">= 100x")
