"""The one-page summary of scripts/gpu-check.sh: `python scripts/gpu_check_summary.py OUT SECONDS` -> OUT/summary.txt.

Reads what the script left in OUT: results.csv (one row per run), native-build.json (the native build's record: dpvo
or droid_slam) and runs/*/log.txt (the method's own line: poses, keyframes, processing fps, PyTorch's peak
allocation). Standard library only.
"""

from __future__ import annotations

import csv
import json
import platform
import re
import subprocess
import sys
import time
from pathlib import Path

COLUMNS = (  # results.csv column, heading, format
    ("direction", "direction", "{}"),
    ("trial", "trial", "{}"),
    ("status", "status", "{}"),
    ("failure", "failure", "{}"),
    ("n_poses", "poses", "{:.0f}"),
    ("coverage", "cov given", "{:.2f}"),
    ("coverage_of_sequence", "cov seq", "{:.2f}"),
    ("wall_s", "wall s", "{:.1f}"),
    ("fps", "fps", "{:.1f}"),
    ("gpu_mem_peak_mb", "GPU MB", "{:.0f}"),
    ("gpu_util_mean_pct", "GPU %", "{:.0f}"),
    ("cpu_mean_pct", "CPU %", "{:.0f}"),
    ("ram_peak_mb", "RAM MB", "{:.0f}"),
    ("ate_rmse", "ATE m", "{:.3f}"),
)
OWN_LINE = re.compile(r"^(?:dpvo|droid_slam): \d+ poses .*$", re.M)
NAMES = {"dpvo": "DPVO", "droid_slam": "DROID-SLAM"}
PAPER = {"dpvo": "DPVO's paper: about 60 fps at its default setting on an RTX 3090."}


def cell(row: dict, key: str, fmt: str) -> str:
    value = row.get(key, "")
    if value in ("", None):
        return "-"
    try:
        return fmt.format(float(value)) if fmt != "{}" else str(value)
    except ValueError:
        return str(value)


def table(rows: list[dict]) -> list[str]:
    heads = [h for _, h, _ in COLUMNS]
    cells = [[cell(r, k, f) for k, _, f in COLUMNS] for r in rows]
    widths = [max(len(x) for x in col) for col in zip(heads, *cells, strict=False)]
    fmt = "  ".join(f"{{:>{w}}}" for w in widths)
    return [fmt.format(*heads)] + [fmt.format(*c) for c in cells]


def means(rows: list[dict], key: str) -> str:
    values = []
    for r in rows:
        try:
            values.append(float(r[key]))
        except (KeyError, TypeError, ValueError):
            continue
    return f"{sum(values) / len(values):.1f}" if values else "-"


def gpu_line() -> str:
    try:
        out = subprocess.run(
            ["nvidia-smi", "--query-gpu=name,driver_version,memory.total,compute_cap", "--format=csv,noheader"],
            capture_output=True,
            text=True,
            timeout=20,
        )
        return out.stdout.strip().splitlines()[0] if out.returncode == 0 and out.stdout.strip() else "(no nvidia-smi)"
    except (OSError, subprocess.SubprocessError):
        return "(no nvidia-smi)"


def summary(out: Path, seconds: float) -> str:
    rows = list(csv.DictReader(open(out / "results.csv"))) if (out / "results.csv").is_file() else []
    try:
        build = json.loads((out / "native-build.json").read_text())
    except (OSError, ValueError):
        build = {}
    method = build.get("method", "dpvo")
    name = NAMES.get(method, method)
    lines = [
        f"slamrun GPU check, {time.strftime('%Y-%m-%d %H:%M:%S')}, {seconds:.0f} s in all, host {platform.node()}",
        f"GPU: {gpu_line()}",
        f"PyTorch {build.get('torch', '?')} (CUDA {build.get('cuda', '?')}), Python {platform.python_version()}",
        f"{name} build: {build.get('source', '?')}, compute capability {build.get('arch', '?')}, "
        f"{build.get('seconds', '?')} s",
        f"network: {build.get('weights', '?')}",
        "",
        f"runs: {len(rows)} ({sum(r.get('status') == 'done' for r in rows)} done)",
        *table(rows),
        "",
        f"means: wall {means(rows, 'wall_s')} s, fps {means(rows, 'fps')}, GPU memory peak "
        f"{means(rows, 'gpu_mem_peak_mb')} MB, GPU utilisation {means(rows, 'gpu_util_mean_pct')} %",
        "fps above: frames fed / the process's wall time (Python, CUDA and network start-up included);",
        f"{name}'s own processing rate is in its log lines below. {PAPER.get(method, '')}".rstrip(),
        "",
    ]
    for log in sorted((out / "runs").glob("*/log.txt")):
        found = OWN_LINE.findall(log.read_text(errors="replace"))
        lines.append(f"{log.parent.name}: {found[-1] if found else f'(no {name} summary line)'}")
    seeds = []  # each trial's seed (engine.plan.trial_seed), from run.json
    for record in sorted((out / "runs").glob("*/run.json")):
        try:
            seeds.append(f"{record.parent.name}: seed {json.loads(record.read_text()).get('seed')}")
        except (OSError, ValueError):
            continue
    lines += ["", "the trials' seeds:", *seeds] if seeds else []
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    folder = Path(sys.argv[1])
    (folder / "summary.txt").write_text(summary(folder, float(sys.argv[2]) if len(sys.argv) > 2 else 0.0))
