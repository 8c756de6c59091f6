"""podman backend: the Docker backend's containers, run by podman, with no daemon.

podman has no resident daemon; slamrun starts `podman system service` on a private socket for as long as the
backend is used (it ends with the backend's close, and with this process even when that is killed with SIGKILL),
and talks to it with the same Docker API client. So every guarantee of the Docker backend holds:
network none, read-only data, CPU set and memory limit, labels for leftovers, capped logs, removal.

Two differences are handled here: podman's default ulimits are above what an unprivileged or sandboxed host
allows (container start fails with "error setting rlimit"), so each container gets this process's own limits;
and images live in podman's store, loaded from an archive `slamrun images --export` writes.
"""

from __future__ import annotations

import ctypes
import os
import resource
import shutil
import signal
import subprocess
import tempfile
import time
from pathlib import Path

from slamrun.backends.docker import DockerBackend, _docker, _reason
from slamrun.errors import DaemonUnreachable, InfraError

IDLE_EXIT_S = 0  # never by itself: an idle exit between two runs would look like a lost engine
START_WAIT_S = 30
# podman's Docker API ignores Docker's `gpu` capability request (containers/podman#22645); from 5.4 it honours a CDI
# device request (containers/podman#25171), for the devices of the CDI spec that `nvidia-ctk cdi generate` writes
CDI_MIN_VERSION = (5, 4)
CDI_ALL_GPUS = "nvidia.com/gpu=all"
STATE_POLL_S = 0.2  # a run's end is seen within this
EXITED = ("exited", "stopped", "dead")  # a container's State.Status once its process has ended


def podman_version(podman: str = "podman") -> tuple[tuple[int, ...], str] | None:
    """podman's version (`podman --version`) as numbers and as printed, or None where it does not answer."""
    try:
        out = subprocess.run([podman, "--version"], capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.SubprocessError):
        return None
    text = out.stdout.split()[-1] if out.returncode == 0 and out.stdout.split() else ""
    numbers = tuple(int(x) for x in text.split("-")[0].split(".") if x.isdigit())
    return (numbers, text) if numbers else None


def gpu_problem(method: str) -> str | None:
    """Why podman here cannot give `method`'s containers the GPU, or None (podman absent: said elsewhere)."""
    found = podman_version()
    if found is None or found[0] >= CDI_MIN_VERSION:
        return None
    return (
        f"{method} needs podman 5.4 or later to give a container the GPU (this is podman {found[1]}, whose Docker "
        "API ignores GPU requests): upgrade podman and write the CDI spec (nvidia-ctk cdi generate "
        "--output=/etc/cdi/nvidia.yaml), or use backend: docker"
    )


def _die_with_parent() -> None:
    """In the service's process: receive SIGTERM when the thread that started it ends (prctl PR_SET_PDEATHSIG;
    the campaign's main thread, or a Dask worker's thread, which closes the backend after each run anyway)."""
    os.setsid()
    ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)


def container_ulimits() -> list:
    """nofile and nproc within what this process may set: its own limits, nproc at most the kernel's pid_max."""
    docker = _docker()
    nofile = resource.getrlimit(resource.RLIMIT_NOFILE)
    nproc = resource.getrlimit(resource.RLIMIT_NPROC)
    try:
        pid_max = int(Path("/proc/sys/kernel/pid_max").read_text())
    except (OSError, ValueError):
        pid_max = 32768
    cap = [pid_max if v == resource.RLIM_INFINITY else min(v, pid_max) for v in nproc]
    return [
        docker.types.Ulimit(name="nofile", soft=nofile[0], hard=nofile[1]),
        docker.types.Ulimit(name="nproc", soft=min(cap), hard=cap[1]),
    ]


class PodmanService:
    """`podman system service` on a private unix socket, owned by this process."""

    def __init__(self):
        self.proc: subprocess.Popen | None = None
        self.dir = Path(tempfile.mkdtemp(prefix="slamrun-podman-"))
        self.socket = self.dir / "podman.sock"
        self.url = f"unix://{self.socket}"

    def start(self) -> str:
        if self.proc is not None and self.proc.poll() is None:
            return self.url
        podman = shutil.which("podman")
        if podman is None:
            raise InfraError("backend: podman needs podman on PATH (Debian: apt-get install podman)")
        self.socket.unlink(missing_ok=True)
        log = open(self.dir / "service.log", "wb")
        self.proc = subprocess.Popen(
            [podman, "system", "service", f"--time={IDLE_EXIT_S}", self.url],
            stdin=subprocess.DEVNULL,
            stdout=log,
            stderr=subprocess.STDOUT,
            cwd=self.dir,  # conmon inherits it and writes an `oom` marker there when the kernel kills a container
            preexec_fn=_die_with_parent,
        )
        log.close()
        deadline = time.monotonic() + START_WAIT_S
        while time.monotonic() < deadline:
            if self.socket.exists():
                return self.url
            if self.proc.poll() is not None:
                break
            time.sleep(0.05)
        said = (self.dir / "service.log").read_text(errors="replace")[-500:]
        self.stop()
        raise InfraError(f"`podman system service` did not start: {said.strip() or 'no output'}")

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.proc = None
        shutil.rmtree(self.dir, ignore_errors=True)


class PodmanBackend(DockerBackend):
    name = "podman"
    follow_logs = False  # podman's followed log stream can end before the last lines of a fast writer

    def __init__(self, sample_interval_s: float = 0.5, client=None):
        super().__init__(sample_interval_s, client)
        self.service = PodmanService()

    @property
    def client(self):
        if self._client is None or self.service.proc is None or self.service.proc.poll() is not None:
            docker = _docker()
            url = self.service.start()
            try:
                self._client = docker.DockerClient(base_url=url, timeout=120)
                self._client.ping()
            except Exception as exc:  # noqa: BLE001 - the service does not answer
                self._client = None
                raise DaemonUnreachable(f"podman's API service at {url} does not answer ({_reason(exc)})") from None
        return self._client

    def daemon_lost(self, exc: BaseException) -> DaemonUnreachable:
        return DaemonUnreachable(
            f"podman's API service stopped answering ({_reason(exc)}): no new run is started. Run the same command "
            "again: finished runs are kept, the others are redone"
        )

    def container_options(self) -> dict:
        return {"ulimits": container_ulimits()}

    @staticmethod
    def exit_status(container, timeout_s: float) -> int | None:
        """The exit status read from the container's state every STATE_POLL_S. Not by `wait`: podman's API service
        answers a wait by polling flat out until the container exits (containers/podman#18150; 1.2-1.3 cores of a
        2-core machine for the whole run, taken from the method it watches), where reading the state costs ~1 %."""
        deadline = time.monotonic() + timeout_s
        while True:
            container.reload()
            state = container.attrs.get("State") or {}
            if state.get("Status") in EXITED:
                return state.get("ExitCode")
            left = deadline - time.monotonic()
            if left <= 0:
                return None
            time.sleep(min(STATE_POLL_S, left))

    @staticmethod
    def gpu_requests() -> list:
        """Every GPU of the host's CDI spec (podman 5.4+: the spec checks refuse an older podman before any run)."""
        return [_docker().types.DeviceRequest(driver="cdi", device_ids=[CDI_ALL_GPUS])]

    def out_of_memory(self, container, exit_code: int | None, req) -> bool:
        """podman reports OOM kills only where conmon sees the cgroup's OOM event (not on cgroup v1 hosts like this
        project's machines, whose kernel still kills at the limit). A container under a memory limit whose main
        process died of SIGKILL (137) that slamrun did not send is taken as out of memory: nothing else in a
        container without network sends it."""
        return super().out_of_memory(container, exit_code, req) or (bool(req.memory_mb) and exit_code == 137)

    def missing_image(self, tag: str, method: str) -> str:
        return (
            f"image {tag} for method {method!r} is not in podman's store; on a machine with Docker: `slamrun images "
            f"--export DIR --method {method}`, then here: `podman load -i DIR/{tag.replace('/', '_')}.tar`"
        )

    def close(self) -> None:
        if self._client is not None:
            try:
                self._client.close()
            except Exception:  # noqa: BLE001
                pass
            self._client = None
        self.service.stop()
