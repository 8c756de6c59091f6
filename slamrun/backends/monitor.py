"""Resource sampling shared by the backends: CPU % (100 % = one core), memory, GPU where NVML exists, and the time
the run's threads waited for a CPU with the machine's CPU pressure over the run (what else the machine ran).

`ResourceSeries` turns samples into the per-run summary columns; GPU columns stay empty (None) when
there is no GPU, never zero.
"""

from __future__ import annotations

import csv
import os
import subprocess
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import psutil

SAMPLE_INTERVAL_S = 0.5
FIELDS = ("t_s", "cpu_pct", "ram_mb", "n_procs", "gpu_mem_mb", "gpu_util_pct")


@dataclass
class Sample:
    t_s: float
    cpu_pct: float
    ram_mb: float
    n_procs: int
    gpu_mem_mb: float | None = None
    gpu_util_pct: float | None = None


@dataclass
class ResourceSeries:
    samples: list[Sample] = field(default_factory=list)
    waited_s: float | None = None  # the run's threads' time runnable but not running, summed (RunQueueWait)
    host_pressure_s: float | None = None  # the time some task on the machine waited for a CPU, over the run
    cpu_s: float | None = None  # the run's CPU time, its tree's or container's, at its last sample

    def summary(self, wall_s: float, n_frames: int | None) -> dict:
        cpu = [s.cpu_pct for s in self.samples[1:]] or [s.cpu_pct for s in self.samples]
        gpu_mem = [s.gpu_mem_mb for s in self.samples if s.gpu_mem_mb is not None]
        gpu_util = [s.gpu_util_pct for s in self.samples if s.gpu_util_pct is not None]
        return {
            "wall_s": wall_s,
            "fps": (n_frames / wall_s) if n_frames and wall_s > 0 else None,
            "cpu_mean_pct": sum(cpu) / len(cpu) if cpu else None,
            "cpu_peak_pct": max(cpu) if cpu else None,
            "ram_peak_mb": max((s.ram_mb for s in self.samples), default=None),
            "gpu_mem_peak_mb": max(gpu_mem) if gpu_mem else None,
            "gpu_util_mean_pct": sum(gpu_util) / len(gpu_util) if gpu_util else None,
            "n_frames": n_frames,
            "cpu_wait_pct": _per_wall(self.waited_s, wall_s),
            "host_cpu_pressure_pct": _per_wall(self.host_pressure_s, wall_s),
            # its threads runnable on average: running (its CPU time) or waiting for a CPU, over its wall time
            "runnable_threads": (self.cpu_s + self.waited_s) / wall_s
            if self.cpu_s is not None and self.waited_s is not None and wall_s > 0
            else None,
        }

    def write_csv(self, path: Path) -> None:
        with open(path, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(FIELDS)
            for s in self.samples:
                w.writerow(
                    [
                        f"{s.t_s:.3f}",
                        f"{s.cpu_pct:.2f}",
                        f"{s.ram_mb:.2f}",
                        s.n_procs,
                        "" if s.gpu_mem_mb is None else f"{s.gpu_mem_mb:.1f}",
                        "" if s.gpu_util_pct is None else f"{s.gpu_util_pct:.1f}",
                    ]
                )


def _per_wall(seconds: float | None, wall_s: float) -> float | None:
    return 100.0 * seconds / wall_s if seconds is not None and wall_s > 0 else None


HOST_PRESSURE = Path("/proc/pressure/cpu")


def host_pressure_s(path: Path = HOST_PRESSURE) -> float | None:
    """The machine's CPU pressure so far (PSI, `some`): seconds in which at least one runnable task waited for a CPU,
    the CPUs averaged weighted by their busy time; None where the kernel does not keep it."""
    try:
        some = next(line for line in path.read_text().splitlines() if line.startswith("some "))
        return int(some.rsplit("total=", 1)[1]) / 1e6
    except (OSError, StopIteration, IndexError, ValueError):
        return None


class RunQueueWait:
    """The time a process tree's threads were runnable but waited for a CPU: the kernel's run delay of each thread
    (/proc/PID/task/TID/schedstat, its second field), the latest value seen per thread, summed; 100 % of the wall
    time is one thread waiting all along. Threads that begin and end between two samples are not seen, and what the
    last thread waited after the last sample is not counted (at most a sample period). And the machine's CPU
    pressure over the same span (host_pressure_s), to tell the run's own threads' competition from the load beside
    it."""

    def __init__(self) -> None:
        self.by_thread: dict[int, float] = {}
        self.host_start = host_pressure_s()

    def sample(self, pids) -> None:
        for pid in pids:
            try:
                tids = os.listdir(f"/proc/{pid}/task")
            except OSError:
                continue
            for tid in tids:
                try:
                    with open(f"/proc/{pid}/task/{tid}/schedstat", "rb") as f:
                        waited = int(f.read().split()[1]) / 1e9
                except (OSError, ValueError, IndexError):
                    continue
                if waited >= self.by_thread.get(int(tid), 0.0):
                    self.by_thread[int(tid)] = waited

    def close(self, series: ResourceSeries) -> ResourceSeries:
        """`series` with the wait and the machine's pressure since this began."""
        series.waited_s = sum(self.by_thread.values()) if self.by_thread else None
        now = host_pressure_s()
        series.host_pressure_s = now - self.host_start if now is not None and self.host_start is not None else None
        return series


UTIL_WINDOW_S = 1.0  # per-process utilisation: NVML's samples of the last second (its sample period is shorter)
NVML_NO_SAMPLE = (0, 6)  # NVML_SUCCESS with no sample, NVML_ERROR_NOT_FOUND: nothing ran kernels in the window


class Gpu:
    """Per-process GPU memory and utilisation through NVML (nvidia-ml-py's `pynvml`), where a GPU and a driver are.

    `nvml` is the NVML module (a stand-in in tests). Memory is what the run's processes hold on all devices; the
    utilisation is the SM % the run's processes used on the busiest device (NVML's per-process samples of the last
    second), or, where a device has no per-process accounting, that device's whole utilisation while the run holds
    memory on it. A device call that fails counts as nothing held and nothing used, and never stops the sampling.
    """

    def __init__(self, nvml=None) -> None:
        self.handles = []
        self.nvml = None
        try:
            if nvml is None:
                import pynvml as nvml  # type: ignore[import-not-found,no-redef]
            nvml.nvmlInit()
            self.handles = [nvml.nvmlDeviceGetHandleByIndex(i) for i in range(nvml.nvmlDeviceGetCount())]
            self.nvml = nvml
        except Exception:  # no library, no driver or no device: the GPU columns stay empty
            self.handles = []

    @property
    def available(self) -> bool:
        return bool(self.handles)

    def sample(self, pids: set[int]) -> tuple[float | None, float | None]:
        """(MB the processes `pids` hold on the GPUs, SM % they used on the busiest GPU); (None, None) without GPU."""
        if not self.handles:
            return None, None
        mem, util = 0.0, 0.0
        for handle in self.handles:
            held = self.memory_mb(handle, pids)
            mem += held
            util = max(util, self.utilisation_pct(handle, pids, held > 0))
        return mem, util

    def memory_mb(self, handle, pids: set[int]) -> float:
        """MB held on one device by the processes `pids` (compute and graphics contexts, each process once)."""
        held: dict[int, int] = {}
        for query in (self.nvml.nvmlDeviceGetComputeRunningProcesses, self.nvml.nvmlDeviceGetGraphicsRunningProcesses):
            try:
                procs = query(handle)
            except self.nvml.NVMLError:
                continue
            for p in procs:
                if p.pid in pids and isinstance(p.usedGpuMemory, int):  # None: the driver does not tell
                    held[p.pid] = max(held.get(p.pid, 0), p.usedGpuMemory)
        return sum(held.values()) / 2**20

    def utilisation_pct(self, handle, pids: set[int], holds_memory: bool) -> float:
        """SM % used on one device by the processes `pids` (their newest samples of the last second, summed)."""
        since_us = int((time.time() - UTIL_WINDOW_S) * 1e6)
        try:
            samples = self.nvml.nvmlDeviceGetProcessUtilization(handle, since_us)
        except self.nvml.NVMLError as err:
            if getattr(err, "value", None) in NVML_NO_SAMPLE:
                return 0.0
            return self._device_utilisation(handle) if holds_memory else 0.0  # no per-process accounting
        newest: dict[int, tuple[int, float]] = {}
        for s in samples:
            if s.pid in pids and s.timeStamp >= newest.get(s.pid, (-1, 0.0))[0]:
                newest[s.pid] = (s.timeStamp, float(s.smUtil))
        return min(100.0, sum(u for _, u in newest.values()))

    def _device_utilisation(self, handle) -> float:
        try:
            return float(self.nvml.nvmlDeviceGetUtilizationRates(handle).gpu)
        except self.nvml.NVMLError:
            return 0.0


def host_gpus(nvml=None, smi: str = "nvidia-smi", timeout_s: float = 10.0) -> list[str]:
    """This host's GPUs, as NVML names them, else as `nvidia-smi -L` lists them; [] when neither answers."""
    try:
        if nvml is None:
            import pynvml as nvml  # type: ignore[import-not-found,no-redef]
        nvml.nvmlInit()
        names = [
            str(nvml.nvmlDeviceGetName(nvml.nvmlDeviceGetHandleByIndex(i))) for i in range(nvml.nvmlDeviceGetCount())
        ]
        if names:
            return names
    except Exception:  # no library, no driver, no device: ask nvidia-smi
        pass
    try:
        out = subprocess.run([smi, "-L"], capture_output=True, text=True, timeout=timeout_s, stdin=subprocess.DEVNULL)
    except (OSError, subprocess.SubprocessError):
        return []
    if out.returncode != 0:
        return []
    return [line.strip() for line in out.stdout.splitlines() if line.startswith("GPU ")]


class ProcessTreeMonitor:
    """Samples a process and all its descendants in a background thread."""

    def __init__(self, pid: int, interval_s: float = SAMPLE_INTERVAL_S, gpu: Gpu | None = None):
        self.root = psutil.Process(pid)
        self.interval_s = interval_s
        self.gpu = gpu
        self.series = ResourceSeries()
        self.known: dict[int, psutil.Process] = {pid: self.root}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, daemon=True, name=f"monitor-{pid}")
        self._t0 = time.monotonic()
        self._last_cpu: float | None = None
        self._last_t = self._t0
        self.wait = RunQueueWait()

    def start(self) -> ProcessTreeMonitor:
        self._thread.start()
        return self

    def stop(self) -> ResourceSeries:
        self._stop.set()
        self._thread.join()
        self.series.cpu_s = self._last_cpu
        return self.wait.close(self.series)

    def descendants(self) -> list[psutil.Process]:
        """Every live process of the tree seen so far (the monitor remembers re-parented children)."""
        return [p for p in self.known.values() if _alive(p)]

    def _loop(self) -> None:
        while not self._stop.is_set():
            self.sample()
            self._stop.wait(self.interval_s)
        self.sample()

    def sample(self) -> None:
        try:
            for child in self.root.children(recursive=True):
                self.known.setdefault(child.pid, child)
        except psutil.Error:
            pass
        cpu_total, rss, procs = 0.0, 0, 0
        for p in list(self.known.values()):
            try:
                with p.oneshot():
                    t = p.cpu_times()
                    cpu_total += t.user + t.system + t.children_user + t.children_system
                    rss += p.memory_info().rss
                    procs += 1
            except psutil.Error:
                continue
        now = time.monotonic()
        if self._last_cpu is None:
            cpu_pct = 0.0
        else:
            cpu_pct = max(0.0, (cpu_total - self._last_cpu) / max(now - self._last_t, 1e-6) * 100.0)
        self._last_cpu, self._last_t = max(cpu_total, self._last_cpu or 0.0), now
        self.wait.sample([pid for pid, p in self.known.items() if _same(p)])
        gmem, gutil = self.gpu.sample(set(self.known)) if self.gpu else (None, None)
        self.series.samples.append(Sample(now - self._t0, cpu_pct, rss / 2**20, procs, gmem, gutil))


def exited(pid: int, timeout_s: float | None = None) -> bool:
    """Whether child process `pid` has exited, waiting up to `timeout_s` (None: until it has) without reaping it: as
    a zombie its /proc entries still hold its last figures (its threads' run delay up to its exit), which a final
    sample then reads before the caller reaps it. A sample taken only after the reaping missed the run's last
    stretch, a whole second or more when the sampler itself waited for a CPU."""
    deadline = None if timeout_s is None else time.monotonic() + timeout_s
    while True:
        try:
            if os.waitid(os.P_PID, pid, os.WEXITED | os.WNOHANG | os.WNOWAIT) is not None:
                return True
        except ChildProcessError:  # reaped already (or not ours): nothing left to wait for
            return True
        if deadline is not None and time.monotonic() >= deadline:
            return False
        time.sleep(0.005 if timeout_s is not None and timeout_s < 0.05 else 0.01)


def _same(p: psutil.Process) -> bool:
    """The process is still the one first seen (its PID not yet reused by another)."""
    try:
        return p.is_running()
    except psutil.Error:
        return False


def tree_pids(root: int) -> list[int]:
    """`root` and its descendants now; [] when it is gone."""
    try:
        proc = psutil.Process(root)
        return [root, *(c.pid for c in proc.children(recursive=True))]
    except psutil.Error:
        return []


def _alive(p: psutil.Process) -> bool:
    try:
        return p.is_running() and p.status() != psutil.STATUS_ZOMBIE
    except psutil.Error:
        return False
