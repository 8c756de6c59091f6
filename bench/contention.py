"""The cost of measuring contention (issue 52): each resource sample reads every thread's run delay
(/proc/PID/task/TID/schedstat) of the run's process tree. Measured side by side in one process: one sample of the
whole monitor (psutil's CPU and memory, the tree's children) against the run-delay part alone, on a real process
tree of 1 process x 4 threads and 4 processes x 4 threads; and a fixed piece of CPU work timed alone and beside a
monitor sampling it every 0.5 s (the runs' rate), alternating 5 times (medians)."""

from __future__ import annotations

import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

from slamrun.backends.monitor import SAMPLE_INTERVAL_S, ProcessTreeMonitor, RunQueueWait, tree_pids

TREE = """
import os, sys, threading, time
children = int(sys.argv[1])
for _ in range(children):
    if os.fork() == 0:
        break
for _ in range(3):
    threading.Thread(target=time.sleep, args=(600,), daemon=True).start()
time.sleep(600)
"""

WORK = "s = 0\nfor i in range(12_000_000):\n    s += i * i\n"


def _per_call_us(fn: Callable[[], None], n: int = 400) -> float:
    fn()
    t0 = time.perf_counter()
    for _ in range(n):
        fn()
    return (time.perf_counter() - t0) / n * 1e6


def _tree(children: int) -> subprocess.Popen:
    proc = subprocess.Popen([sys.executable, "-c", TREE, str(children)])
    deadline = time.monotonic() + 10
    while len(tree_pids(proc.pid)) < children + 1 and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(0.3)  # the threads started
    return proc


def _work_s(monitored: bool) -> float:
    proc = subprocess.Popen([sys.executable, "-c", WORK])
    monitor = ProcessTreeMonitor(proc.pid).start() if monitored else None
    t0 = time.perf_counter()
    proc.wait()
    took = time.perf_counter() - t0
    if monitor is not None:
        monitor.stop()
    return took


def bench_contention(tmp: Path, report: Callable[[str, str, str], None]) -> None:
    print("contention: the cost of reading each thread's run delay with every resource sample")
    for children, what in ((0, "1 process x 4 threads"), (3, "4 processes x 4 threads")):
        proc = _tree(children)
        try:
            pids = tree_pids(proc.pid)
            monitor = ProcessTreeMonitor(proc.pid)
            whole = _per_call_us(monitor.sample)
            wait = RunQueueWait()
            delay = _per_call_us(lambda pids=pids, wait=wait: wait.sample(pids))
        finally:
            for pid in reversed(tree_pids(proc.pid)):
                subprocess.run(["kill", "-9", str(pid)], check=False)
            proc.wait()
        report(f"one sample, {what}: the whole monitor", f"{whole:.0f} us", "-")
        share = 100 * delay / whole
        report(f"  of it the run delays ({len(pids) * 4} threads)", f"{delay:.0f} us ({share:.0f} %)", "-")
        cpu = 100 * delay * 1e-6 / SAMPLE_INTERVAL_S
        report(f"  the run delays' CPU at one sample per {SAMPLE_INTERVAL_S:g} s", f"{cpu:.4f} % of a core", "< 0.1 %")
    alone, beside = [], []
    for _ in range(5):
        alone.append(_work_s(False))
        beside.append(_work_s(True))
    a, b = statistics.median(alone), statistics.median(beside)
    report("a fixed CPU task alone (median of 5)", f"{a:.3f} s", "-")
    report(
        "  the same, monitored (contention included), alternating",
        f"{b:.3f} s ({100 * (b - a) / a:+.1f} %)",
        "within noise (< 2 %)",
    )
