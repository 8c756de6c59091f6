"""A real single-node Slurm cluster for the tests: Debian's munged, slurmctld and slurmd on 127.0.0.1 only
(CommunicationParameters=NoCtldInAddrAny,NoInAddrAny), with their own munge socket, ports, state and spool in a
temporary folder, so nothing of the machine's own configuration is read or changed. Root only (slurmd)."""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import socket
import subprocess
import tempfile
import time
from pathlib import Path

DAEMONS = ("munged", "slurmctld", "slurmd")
MUNGE_KEY = Path("/etc/munge/munge.key")


def missing() -> str | None:
    """Why a cluster cannot be started here, or None."""
    absent = [d for d in DAEMONS if shutil.which(d) is None and not Path("/usr/sbin", d).exists()]
    if absent:
        return f"Slurm/munge not installed ({', '.join(absent)} missing; Debian: apt-get install slurm-wlm munge)"
    if os.getuid() != 0:
        return "slurmd runs jobs as their users: the test cluster needs root"
    if not MUNGE_KEY.exists():
        return f"{MUNGE_KEY} missing (the munge package creates it)"
    return None


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _daemon(name: str) -> str:
    return shutil.which(name) or str(Path("/usr/sbin", name))


class SlurmCluster:
    """Start with `start()`, stop with `stop()`; `env` holds SLURM_CONF for every Slurm command."""

    def __init__(self, cpus: int = 2, memory_mb: int = 4000, partition: str = "debug"):
        self.dir = Path(tempfile.mkdtemp(prefix="slurm-", dir="/tmp"))  # short: unix socket paths
        self.cpus, self.memory_mb, self.partition = cpus, memory_mb, partition
        self.conf = self.dir / "slurm.conf"
        self.env = {"SLURM_CONF": str(self.conf)}

    def write_conf(self) -> None:
        d, host = self.dir, socket.gethostname()
        for sub in ("state", "spool", "log"):
            (d / sub).mkdir(exist_ok=True)
        self.conf.write_text(
            f"""ClusterName=slamrun-test
SlurmctldHost={host}(127.0.0.1)
SlurmctldPort={_free_port()}
SlurmdPort={_free_port()}
CommunicationParameters=NoCtldInAddrAny,NoInAddrAny
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket={d}/munge.sock
CredType=cred/munge
StateSaveLocation={d}/state
SlurmdSpoolDir={d}/spool
SlurmctldPidFile={d}/slurmctld.pid
SlurmdPidFile={d}/slurmd.pid
SlurmctldLogFile={d}/log/slurmctld.log
SlurmdLogFile={d}/log/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
JobRequeue=0
ReturnToService=2
MpiDefault=none
KillWait=5
NodeName={host} NodeAddr=127.0.0.1 CPUs={self.cpus} RealMemory={self.memory_mb} State=UNKNOWN
PartitionName={self.partition} Nodes={host} Default=YES MaxTime=INFINITE State=UP
"""
        )

    def run(self, *argv: str, check: bool = True) -> subprocess.CompletedProcess:
        return subprocess.run(argv, env={**os.environ, **self.env}, capture_output=True, text=True, check=check)

    def start(self, timeout: float = 60) -> SlurmCluster:
        self.write_conf()
        d = self.dir
        subprocess.run(
            [_daemon("munged"), f"--socket={d}/munge.sock", f"--key-file={MUNGE_KEY}", f"--pid-file={d}/munged.pid"]
            + [f"--log-file={d}/log/munged.log", f"--seed-file={d}/munge.seed", "--force"],
            check=True,
        )
        env = {**os.environ, **self.env}
        subprocess.run([_daemon("slurmctld"), "-f", str(self.conf)], env=env, check=True)
        subprocess.run([_daemon("slurmd"), "-f", str(self.conf)], env=env, check=True)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            out = self.run("sinfo", "-h", "-o", "%T", check=False)
            if out.returncode == 0 and out.stdout.strip() == "idle":
                return self
            time.sleep(0.5)
        raise RuntimeError(f"the test Slurm did not come up within {timeout:.0f} s:\n{self.logs()}")

    def logs(self) -> str:
        return "\n".join(
            f"--- {p.name}\n" + p.read_text(errors="replace")[-2000:] for p in sorted((self.dir / "log").glob("*.log"))
        )

    def jobs(self) -> list[tuple[str, str, str]]:
        """(id, name, state) of every job Slurm knows."""
        out = self.run("squeue", "-h", "-o", "%i|%j|%T", check=False).stdout
        return [tuple(line.split("|")) for line in out.splitlines() if line]  # type: ignore[misc]

    def stop(self) -> None:
        self.run("scancel", "--user", "root", check=False)
        deadline = time.monotonic() + 30
        while self.jobs() and time.monotonic() < deadline:
            time.sleep(0.5)
        for name in ("slurmd", "slurmctld", "munged"):
            pidfile = self.dir / f"{name}.pid"
            with contextlib.suppress(OSError, ValueError):
                pid = int(pidfile.read_text())
                os.kill(pid, signal.SIGTERM)
                for _ in range(100):
                    os.kill(pid, 0)
                    time.sleep(0.1)
                os.kill(pid, signal.SIGKILL)
        shutil.rmtree(self.dir, ignore_errors=True)
