"""Docker backend: one container per run, with the container contract of the architecture.

/data is the prepared view (read-only), /work the run's work directory (read-write), no network, a
non-root user where the image has one, the lane's CPU set and memory limit, a GPU when the method needs
one and the host has one. The wall-clock timeout is enforced from outside; the exit code, OOM kill and
logs are read back; the container is always removed. Containers carry labels (campaign, run) so a
runner that was killed leaves nothing behind once it starts again.
"""

from __future__ import annotations

import os
import threading
import time
from pathlib import Path

from slamrun.backends.base import Defaults, ExecRequest, ExecResult, OutputWatch, supervise, supervised_result
from slamrun.backends.logcap import CappedLog, Tap
from slamrun.backends.monitor import Gpu, ResourceSeries, RunQueueWait, Sample, tree_pids
from slamrun.datasets.view import PreparedView
from slamrun.errors import DaemonUnreachable, InfraError
from slamrun.results.catalogue import FPS, N_FRAMES, WALL_S

DATA = Path("/data")
WORK = Path("/work")
CONTAINER_UID = 1000  # the non-root user our images create; a root host hands /work to it
LABEL_CAMPAIGN = "slamrun.campaign"
LABEL_RESULTS = "slamrun.results"  # the results folder's identity (its ledger's results_id)
LABEL_RUN = "slamrun.run"
# After a container exits, its log stream is read on while bytes still come (a loaded engine sends a flooded log
# slowly); one that sends nothing for this long is cut off, and the rest is read from the engine's stored log.
LOG_STALL_S = 5.0


def docker_host() -> str:
    """Where the Docker client looks for the daemon."""
    return os.environ.get("DOCKER_HOST") or "unix:///var/run/docker.sock"


def _reason(exc: BaseException) -> str:
    """The innermost cause of a requests/urllib3 error, e.g. 'Connection refused'."""
    text = str(exc)
    for marker in ("Connection refused", "No such file or directory", "Connection aborted", "Connection reset"):
        if marker in text:
            return marker
    return text[:200]


def _timed_out(exc: BaseException) -> bool:
    """A wait that timed out (the container still runs), as requests reports it over TCP or a unix socket."""
    import requests

    return isinstance(exc, requests.exceptions.ReadTimeout) or "timed out" in str(exc).lower()


def _timestamp(text: str):
    """Docker's RFC 3339 time with nanoseconds, to a datetime (microseconds)."""
    from datetime import datetime

    main, _, frac = text.rstrip("Z").partition(".")
    return datetime.fromisoformat(f"{main}.{(frac + '000000')[:6]}+00:00")


def _docker():
    try:
        import docker
    except ImportError:
        raise InfraError("the docker Python package is missing; `pip install docker` (make install does it)") from None
    return docker


class DockerBackend(Defaults):
    name = "docker"
    follow_logs = True  # the log is pumped while the container runs (False: read once it has exited)

    def __init__(self, sample_interval_s: float = 0.5, client=None):
        self.sample_interval_s = sample_interval_s
        self._client = client
        self.gpu = Gpu()

    @property
    def client(self):
        if self._client is None:
            docker = _docker()
            try:
                self._client = docker.from_env(timeout=120)
                self._client.ping()
            except Exception as exc:  # noqa: BLE001 - any failure here means: no daemon to talk to
                self._client = None
                raise DaemonUnreachable(
                    f"Docker daemon unreachable at {docker_host()} ({_reason(exc)}); start it "
                    "(scripts/start-dockerd.sh, or `systemctl start docker`) or use backend: local"
                ) from None
        return self._client

    def daemon_answers(self) -> bool:
        try:
            self.client.api.ping()
            return True
        except Exception:  # noqa: BLE001 - refused, socket gone, aborted: no daemon
            return False

    def daemon_lost(self, exc: BaseException) -> DaemonUnreachable:
        return DaemonUnreachable(
            f"Docker daemon unreachable at {docker_host()} ({_reason(exc)}): no new run is started. Start it again "
            "(scripts/start-dockerd.sh, or `systemctl start docker`) and run the same command: finished runs are "
            "kept, a run whose container completed meanwhile is collected, the others are redone"
        )

    # ------------------------------------------------------------ before the first run
    def check(self, images: dict[str, str | None] | None = None) -> None:
        """The daemon answers and every method's image exists; one error lists every missing image."""
        client = self.client
        docker = _docker()
        problems = []
        for method, tag in (images or {}).items():
            if tag is None:
                problems.append(f"method {method!r} has no Docker image; run it with backend: local")
                continue
            try:
                client.images.get(tag)
            except docker.errors.ImageNotFound:
                problems.append(self.missing_image(tag, method))
        if problems:
            raise InfraError(f"{self.name} images:\n  " + "\n  ".join(problems))

    def missing_image(self, tag: str, method: str) -> str:
        return f"image {tag} for method {method!r} is missing; build it: make images METHOD={method}"

    @staticmethod
    def gpu_requests() -> list:
        """How a container is given the host's GPUs: the NVIDIA runtime's `gpu` capability, every GPU."""
        return [_docker().types.DeviceRequest(count=-1, capabilities=[["gpu"]])]

    def container_options(self) -> dict:
        """Engine-specific options of every container (none for Docker)."""
        return {}

    def describe_image(self, tag: str) -> dict:
        """The image a run used: its id and the slamrun.* labels its build recorded (sources and commits,
        vocabulary, weights, target), for run.json. Cached per tag."""
        cache = self.__dict__.setdefault("_image_info", {})
        if tag not in cache:
            try:
                info = self.client.api.inspect_image(tag)
            except Exception:  # noqa: BLE001 - the run itself reports a missing image
                return {"tag": tag}
            labels = (info.get("Config") or {}).get("Labels") or {}
            cache[tag] = {"tag": tag, "id": info.get("Id")} | {
                k.removeprefix("slamrun."): v for k, v in labels.items() if k.startswith("slamrun.")
            }
        return cache[tag]

    def leftovers(self, campaign: str, results_id: str = "") -> list:
        """Containers of this campaign and results folder that a killed runner or a lost daemon left behind (also
        those of the campaign without a results label, started before containers carried one); never those of the
        same campaign run into another results folder."""
        found = self.client.containers.list(all=True, filters={"label": f"{LABEL_CAMPAIGN}={campaign}"})
        return [c for c in found if (c.labels or {}).get(LABEL_RESULTS, results_id) == results_id]

    @staticmethod
    def collect(container, log_path: Path, log_cap_bytes: int, n_frames: int) -> ExecResult | None:
        """The result of a leftover container that exited by itself (None while it runs, or when it never
        started): its exit code, its wall time from the daemon's record and its log. The resource samples
        were lost with the runner that took them; only wall time and fps are known."""
        state = container.attrs.get("State") or {}
        if state.get("Status") != "exited" or not state.get("StartedAt") or not state.get("FinishedAt"):
            return None
        wall_s = (_timestamp(state["FinishedAt"]) - _timestamp(state["StartedAt"])).total_seconds()
        if wall_s <= 0:
            return None
        log = CappedLog(log_path, log_cap_bytes)
        try:
            log.write(container.logs(stdout=True, stderr=True))
        finally:
            log.close()
        return ExecResult(
            exit_code=state.get("ExitCode"),
            wall_s=wall_s,
            oom=bool(state.get("OOMKilled")),
            log_truncated=log.truncated,
            resources={WALL_S: wall_s, FPS: n_frames / wall_s if n_frames else None, N_FRAMES: n_frames},
        )

    def process_paths(self, view: PreparedView, workdir: Path) -> tuple[PreparedView, Path]:
        return view.at(DATA), WORK

    # ------------------------------------------------------------ one run
    def execute(self, req: ExecRequest, cancel: threading.Event, on_start=None) -> ExecResult:
        docker = _docker()
        if req.image is None:
            raise InfraError("this method has no Docker image; run it with backend: local")
        user = None
        if os.getuid() == 0:  # the work folder and what the adapter wrote in it (DynaSLAM's masks/) to the user
            for folder, dirs, files in os.walk(req.workdir):
                for name in [folder, *(os.path.join(folder, n) for n in dirs + files)]:
                    os.chown(name, CONTAINER_UID, CONTAINER_UID, follow_symlinks=False)
            user = f"{CONTAINER_UID}:{CONTAINER_UID}"
        else:
            user = f"{os.getuid()}:{os.getgid()}"
        kwargs = dict(
            image=req.image,
            command=req.argv,
            detach=True,
            network_mode="none",
            working_dir=str(WORK),
            user=user,
            labels={**req.labels},
            volumes={
                str(req.view.root): {"bind": str(DATA), "mode": "ro"},
                str(req.workdir): {"bind": str(WORK), "mode": "rw"},
            },
            environment={"HOME": str(WORK), "MPLBACKEND": "Agg", **req.env},
            **self.container_options(),
        )
        if req.cpus:
            kwargs["cpuset_cpus"] = ",".join(str(c) for c in req.cpus)
        if req.memory_mb:
            kwargs["mem_limit"] = f"{req.memory_mb}m"
            kwargs["memswap_limit"] = f"{req.memory_mb}m"
        if req.needs_gpu and self.gpu.available:
            kwargs["device_requests"] = self.gpu_requests()
        try:
            container = self.client.containers.create(**kwargs)
        except docker.errors.ImageNotFound:
            raise InfraError(f"image {req.image} is missing; build it: make images") from None
        except docker.errors.APIError as exc:
            raise InfraError(f"docker could not create the container: {exc.explanation or exc}") from None
        except Exception as exc:  # noqa: BLE001 - requests' ConnectionError: is the daemon there?
            if not self.daemon_answers():
                raise self.daemon_lost(exc) from None
            raise
        daemon_lost = False
        try:
            log = CappedLog(req.log_path, req.log_cap_bytes)  # may fail on a full disk: still remove the container
            return self._run(container, req, cancel, log, on_start)
        except DaemonUnreachable:
            daemon_lost = True  # the container is left for the next start to collect or remove
            raise
        finally:
            if not daemon_lost:
                try:
                    container.remove(force=True)
                except docker.errors.NotFound:
                    pass
                except Exception as exc:  # noqa: BLE001 - the daemon went away: the next start removes it by label
                    if not self.daemon_answers():
                        raise self.daemon_lost(exc) from None
                    raise InfraError(f"could not remove container {container.short_id}: {exc}") from None

    def _run(self, container, req: ExecRequest, cancel: threading.Event, log: CappedLog, on_start) -> ExecResult:
        docker = _docker()
        t0 = time.monotonic()
        try:
            container.start()
        except docker.errors.APIError as exc:
            log.close()
            raise InfraError(f"docker could not start the container: {exc.explanation or exc}") from None
        except Exception as exc:  # noqa: BLE001 - requests' ConnectionError: is the daemon there?
            log.close()
            if not self.daemon_answers():
                raise self.daemon_lost(exc) from None
            raise
        if on_start:
            on_start(0, 0.0)
        tap = Tap(log)
        pump = threading.Thread(target=self._pump_logs, args=(container, tap, self.follow_logs), daemon=True)
        if self.follow_logs:
            pump.start()
        monitor = ContainerMonitor(container, self.sample_interval_s, t0, self.gpu if req.needs_gpu else None)
        monitor.start()
        exit_code = None

        def step(remaining: float) -> bool:
            nonlocal exit_code
            try:
                exit_code = self.exit_status(container, min(0.2, max(remaining, 0.01)))
            except Exception as exc:  # noqa: BLE001 - requests' ConnectionError, or a dead daemon
                if self.daemon_answers():
                    return False
                raise self.daemon_lost(exc) from None
            return exit_code is not None

        try:
            timed_out, cancelled, exceeded = supervise(step, t0, req.timeout_s, cancel, OutputWatch.of(req))
        except DaemonUnreachable:
            monitor.stop()
            log.close()
            raise
        if exit_code is None:
            try:
                container.kill()
            except docker.errors.APIError:
                pass
            try:
                exit_code = self.exit_status(container, 30)
            except Exception:  # noqa: BLE001
                exit_code = None
        wall_s = time.monotonic() - t0
        series = monitor.stop()
        if not self.follow_logs:
            pump.start()  # the whole log, now that the container has exited
        self._read_log_to_end(container, pump, tap, log)
        log.close()
        oom = self.out_of_memory(container, exit_code, req)
        return supervised_result(req, series, exit_code, wall_s, (timed_out, cancelled, exceeded), log.truncated, oom)

    @staticmethod
    def exit_status(container, timeout_s: float) -> int | None:
        """The container's exit status once it has exited, waiting at most `timeout_s`; None while it runs."""
        try:
            return container.wait(timeout=timeout_s).get("StatusCode")
        except Exception as exc:  # noqa: BLE001 - requests' ReadTimeout is the answer "still running"
            if _timed_out(exc):
                return None
            raise

    @staticmethod
    def out_of_memory(container, exit_code: int | None, req: ExecRequest) -> bool:
        """The engine's own verdict: the kernel's OOM killer ended the container."""
        try:
            container.reload()
            return bool(container.attrs["State"].get("OOMKilled"))
        except _docker().errors.APIError:
            return False

    @staticmethod
    def _read_log_to_end(container, pump: threading.Thread, tap: Tap, log: CappedLog) -> None:
        """All of an exited container's output in `log`. The stream read so far is read on while bytes come, then cut
        off; a followed stream can end before the last lines under load or hang after the exit (docker/docker-py#3084),
        so the rest comes from the engine's stored log, past the bytes already had (podman's read after the exit can
        break off too)."""
        log.wait_for(pump, LOG_STALL_S)
        tap.cut()
        skip = log.received
        try:
            for chunk in container.logs(stream=True, follow=False, stdout=True, stderr=True):
                if skip >= len(chunk):
                    skip -= len(chunk)
                    continue
                log.write(chunk[skip:])
                skip = 0
        except Exception as exc:  # noqa: BLE001 - the engine went away: say so where the output ends
            log.cut_short = f"the engine's stored log could not be read after the exit ({exc}): its end may be missing"

    @staticmethod
    def _pump_logs(container, log: CappedLog | Tap, follow: bool = True) -> None:
        try:
            for chunk in container.logs(stream=True, follow=follow, stdout=True, stderr=True):
                log.write(chunk)
        except Exception:  # noqa: BLE001 - the container is gone: the log ends here
            pass


def _in_container(pid: int, container_id: str) -> bool:
    """Whether this machine's process `pid` runs in the container (its cgroup path names the container's id)."""
    try:
        return container_id in Path(f"/proc/{pid}/cgroup").read_text()
    except OSError:
        return False


class ContainerMonitor:
    """Samples a container's cgroup figures (CPU time, memory) from the Docker stats API at a fixed rate."""

    def __init__(self, container, interval_s: float, t0: float, gpu: Gpu | None = None):
        self.container = container
        self.gpu = gpu if gpu is not None and gpu.available else None
        self.interval_s = interval_s
        self.t0 = t0
        self.series = ResourceSeries()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, daemon=True, name="container-monitor")
        self._last: tuple[float, int] | None = None
        self.wait = RunQueueWait()
        self._host_pid: int | None = None  # the container's first process, as this machine numbers it

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> ResourceSeries:
        self._stop.set()
        self._thread.join(timeout=10)
        self.series.cpu_s = self._last[1] / 1e9 if self._last is not None else None  # the cgroup's CPU time
        return self.wait.close(self.series)

    def _sample_wait(self) -> None:
        """The container's threads' wait for a CPU, read from this machine's /proc: its first process's PID from the
        engine once, taken only where that process's cgroup names the container (an engine on another machine numbers
        its own processes: then nothing is counted, and the columns stay empty), its tree from /proc at each sample."""
        if self._host_pid is None:
            try:
                self.container.reload()
                pid = int(self.container.attrs["State"]["Pid"])
            except Exception:  # noqa: BLE001 - not running yet, or gone
                return
            self._host_pid = pid if pid > 0 and _in_container(pid, self.container.id) else 0
        if self._host_pid:
            self.wait.sample(tree_pids(self._host_pid))

    def _loop(self) -> None:
        """One sample every interval_s from the first: the stats call's own time (up to a second on a busy engine) is
        not added to the period; when a call outlasts it, the next one starts at once, with no burst to catch up."""
        due = time.monotonic()
        while not self._stop.is_set():
            self.sample()
            now = time.monotonic()
            due = max(due + self.interval_s, now)
            self._stop.wait(due - now)

    def sample(self) -> None:
        try:
            s = self.container.stats(stream=False, one_shot=True)
        except Exception:  # noqa: BLE001 - the container ended between two samples
            return
        now = time.monotonic()
        cpu_ns = (s.get("cpu_stats") or {}).get("cpu_usage", {}).get("total_usage")
        mem = s.get("memory_stats") or {}
        if cpu_ns is None or "usage" not in mem:
            return  # not running (yet, or any more)
        stats = mem.get("stats") or {}
        # cgroup v1 counts page cache in usage; v2 names it inactive_file
        cache = stats.get("total_inactive_file", stats.get("inactive_file", stats.get("cache", 0)))
        ram_mb = max(mem["usage"] - cache, 0) / 2**20
        if self._last is None:
            cpu_pct = 0.0
        else:
            dt = now - self._last[0]
            cpu_pct = max(0.0, (cpu_ns - self._last[1]) / 1e9 / max(dt, 1e-6) * 100.0)
        self._last = (now, cpu_ns)
        n_procs = (s.get("pids_stats") or {}).get("current") or 0
        self._sample_wait()
        gmem = gutil = None
        if self.gpu is not None:
            try:
                top = self.container.top()
                col = top["Titles"].index("PID")
                pids = {int(p[col]) for p in top["Processes"]}
                gmem, gutil = self.gpu.sample(pids)
            except Exception:  # noqa: BLE001 - the container ended
                pass
        self.series.samples.append(Sample(now - self.t0, cpu_pct, ram_mb, n_procs, gmem, gutil))
