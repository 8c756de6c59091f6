"""Which machine ran a run, and on which Python packages: recorded in each run's run.json (and the ledger's host and
packages columns), so that a figure can be traced to the node and the library versions that produced it."""

from __future__ import annotations

import functools
import os
import platform
import shutil
import subprocess
from pathlib import Path

from slamrun.core.inputs import read_text_bounded
from slamrun.errors import SlamRunError


@functools.cache
def machine() -> dict:
    """This host: its name, CPU model and logical cores, GPUs (NVML or nvidia-smi; [] without), and where Slurm
    placed the process, its node and job (None outside Slurm). Looked up once per process."""
    from slamrun.backends.monitor import host_gpus

    return {
        "name": platform.node() or "unknown",
        "cpu": cpu_model(),
        "cores": os.cpu_count(),
        "gpus": host_gpus(),
        "slurm_node": os.environ.get("SLURMD_NODENAME"),
        "slurm_job": os.environ.get("SLURM_JOB_ID"),
    }


def cpu_model() -> str:
    """The CPU's model name from /proc/cpuinfo, else what platform says."""
    try:
        for line in read_text_bounded("/proc/cpuinfo", 4 << 20, "CPU information").splitlines():
            if line.lower().startswith(("model name", "hardware", "cpu model")):
                return line.split(":", 1)[1].strip()
    except SlamRunError:
        pass
    return platform.processor() or "unknown model"


@functools.cache
def _distributions() -> dict[str, list[str]]:
    from importlib.metadata import packages_distributions

    return packages_distributions()


def package_versions(modules: tuple[str, ...]) -> dict[str, str]:
    """The installed distributions that provide the import names `modules` (cv2 -> opencv-python-headless), with
    their versions, as this interpreter has them; a module no distribution provides is 'not installed'."""
    from importlib.metadata import PackageNotFoundError, version

    out: dict[str, str] = {}
    for module in modules:
        dists = _distributions().get(module) or []
        if not dists:
            out[module] = "not installed"
        for dist in dists:
            try:
                out[dist] = version(dist)
            except PackageNotFoundError:
                out[dist] = "not installed"
    return out


def packages_text(versions: dict[str, str]) -> str | None:
    """`versions` on one line, as results.csv's packages column holds them ('numpy 2.4.6, scipy 1.17.1')."""
    return ", ".join(f"{k} {v}" for k, v in sorted(versions.items())) or None


@functools.cache
def source_commit() -> str:
    """The git commit of slamrun's source tree (`+ local changes` where it differs from it), where it is a git
    checkout and git is installed; else why not. Recorded with every run (the code that ran it) and by the report
    (the code that wrote it); looked up once per process."""
    root = Path(__file__).resolve().parents[2]
    git = shutil.which("git")
    if git is None or not (root / ".git").exists():
        return "not known (slamrun is not run from a git checkout)"
    try:
        head = subprocess.run([git, "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True, timeout=10)
        dirty = subprocess.run(
            [git, "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
            capture_output=True,
            text=True,
            timeout=10,
        )
    except (OSError, subprocess.TimeoutExpired) as exc:
        return f"not known ({exc})"
    if head.returncode != 0:
        return f"not known ({head.stderr.strip()[:200]})"
    return head.stdout.strip() + (" + local changes" if dirty.stdout.strip() else "")
