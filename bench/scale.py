"""make bench: scale (one figure set, measured side by side with its baseline)."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

from bench.common import report


def bench_scale(tmp: Path, n_runs: int = 10_000) -> None:
    """The study's scale: a 10,000-run plan of a trivial method through the command line (its live output, not
    a terminal), the finish time of every run read from its output line; the rate over the first minute and
    around 50 % done side by side, the ETA printed at 10 % against the time that really remained, and `slamrun
    status` on the finished 10,000-row ledger as a whole process."""
    import re

    import yaml

    from slamrun.datasets.make_synthetic import generate

    print(f"scale: a {n_runs:,}-run plan of a no-op method, 2 lanes, through `slamrun campaign`")
    generate(tmp / "data" / "s", frames=30, seed=0, size=(64, 48))
    spec = {
        "name": "scale",
        "results": str(tmp / "res"),
        "cache": str(tmp / "cache"),
        "datasets": [{"name": "d", "path": str(tmp / "data"), "sequences": ["s"]}],
        "methods": [{"name": "external", "params": {"argv": ["/bin/true"]}}],
        "directions": ["forward"],
        "trials": n_runs,
        "lanes": 2,
        "report": False,
        "evaluate": False,
    }
    slamrun = str(Path(sys.executable).parent / "slamrun")
    # the first 10 % as a campaign of its own, then the dry run's estimate of the rest
    (tmp / "scale.yaml").write_text(yaml.safe_dump(spec | {"trials": n_runs // 10}))
    subprocess.run([slamrun, "campaign", str(tmp / "scale.yaml")], check=True, capture_output=True)
    (tmp / "scale.yaml").write_text(yaml.safe_dump(spec))
    dry = subprocess.run([slamrun, "plan", str(tmp / "scale.yaml")], check=True, capture_output=True, text=True)
    m = re.search(r"estimated duration: (?:(\d+) h )?(?:(\d+) min )?(\d+) s", dry.stdout)
    dry_s = None if m is None else sum(f * int(v or 0) for f, v in zip((3600, 60, 1), m.groups(), strict=True))
    n_runs -= n_runs // 10  # what the campaign below runs
    t0 = time.monotonic()
    proc = subprocess.Popen([slamrun, "campaign", str(tmp / "scale.yaml")], stdout=subprocess.PIPE, text=True)
    finished: list[float] = []
    eta_at_10 = None
    for line in proc.stdout:
        now = time.monotonic() - t0
        if re.match(r"\[lane \d+\] \S+: (done|failed) \(", line):
            finished.append(now)
        elif line.startswith("progress:") and eta_at_10 is None and len(finished) >= n_runs // 10:
            m = re.search(r"ETA (?:(\d+) h )?(?:(\d+) min )?(\d+) s", line)
            if m:
                h, mi, sec = (int(v) if v else 0 for v in m.groups())
                eta_at_10 = (now, 3600 * h + 60 * mi + sec)
    proc.wait()
    end = finished[-1] if finished else 0.0
    first = [t for t in finished if t <= finished[0] + 60] if finished else []
    rate_first = (len(first) - 1) / max(first[-1] - first[0], 1e-9) if len(first) > 1 else 0.0
    mid = finished[int(0.45 * len(finished)) : int(0.55 * len(finished))]
    rate_mid = (len(mid) - 1) / max(mid[-1] - mid[0], 1e-9) if len(mid) > 1 else 0.0
    report(f"runs finished of {n_runs:,}", f"{len(finished):,}", f"{n_runs:,}")
    report("rate over the first minute", f"{rate_first:.1f} runs/s", ">= 25 runs/s")
    report("rate around 50 % done (45-55 %)", f"{rate_mid:.1f} runs/s", "-")
    report("  ratio 50 % / first minute", f"{rate_mid / max(rate_first, 1e-9):.2f}", "0.8 - 1.2")
    if eta_at_10 is not None:
        at, said = eta_at_10
        real = end - at
        report("ETA printed at 10 % done", f"{said:.0f} s", "-")
        report("  time that really remained", f"{real:.0f} s", "-")
        report("  ETA error", f"{100 * abs(said - real) / max(real, 1e-9):.1f} %", "<= 25 %")
    if dry_s is not None:
        report("dry run's estimate of the 90 % left", f"{dry_s:.0f} s", "-")
        report("  their real duration (process start to last run)", f"{end:.0f} s", "-")
        report("  dry-run estimate error", f"{100 * abs(dry_s - end) / max(end, 1e-9):.1f} %", "<= 25 %")
    t1 = time.perf_counter()
    subprocess.run([slamrun, "status", str(tmp / "res"), "--json"], check=True, capture_output=True)
    status_s = time.perf_counter() - t1
    report(f"slamrun status on the {n_runs + n_runs // 9:,}-row ledger (whole process)", f"{status_s:.2f} s", "< 1 s")
