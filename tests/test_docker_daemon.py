"""The Docker daemon dies mid-run: a real second dockerd (its own socket, data, containerd and network
namespace) is killed with SIGKILL while a container runs, then started again. The campaign must notice
within seconds, name the daemon, stop starting runs, and on the next start collect the run whose container
completed while the daemon was away, redo nothing that finished, and finish the rest."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import threading
import time
from pathlib import Path

import pytest

from slamrun.engine.campaign import run_campaign
from slamrun.engine.spec_file import load_spec
from slamrun.errors import DaemonUnreachable
from tests.conftest import one_sequence, write_spec
from tests.test_campaign import ledger_rows
from tests.test_docker import _unavailable

BASE = "debian:bookworm-slim"


class Daemon:
    """A dockerd of the test's own, started and killed at will."""

    def __init__(self, root: Path):
        self.root = root
        self.sock = root / "docker.sock"
        self.host = f"unix://{self.sock}"
        self.proc: subprocess.Popen | None = None

    def start(self) -> None:
        args = [  # in a network namespace of its own: `--bridge none` would delete the host's docker0 otherwise
            "unshare",
            "--net",
            "dockerd",
            "--host",
            self.host,
            "--data-root",
            str(self.root / "data"),
            "--exec-root",
            str(self.root / "exec"),
            "--pidfile",
            str(self.root / "docker.pid"),
            "--bridge",
            "none",
            "--iptables=false",
        ]
        log = open(self.root / "dockerd.log", "a")
        self.proc = subprocess.Popen(args, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
        for _ in range(120):
            if self.answers():
                return
            time.sleep(0.25)
        raise RuntimeError(f"the test's dockerd did not answer; see {self.root / 'dockerd.log'}")

    def answers(self) -> bool:
        return self.docker("info", check=False).returncode == 0

    def docker(self, *args: str, check: bool = True, **kw) -> subprocess.CompletedProcess:
        return subprocess.run(["docker", "-H", self.host, *args], capture_output=True, check=check, **kw)

    def kill(self) -> None:
        """SIGKILL, as a crash: the daemon's own containerd goes with it, the container's shim stays."""
        self.proc.send_signal(signal.SIGKILL)
        self.proc.wait()

    def cleanup(self) -> None:
        """What a killed daemon can leave: its containerd and shims, and the mounts under its folders."""
        import psutil

        for p in psutil.process_iter(["cmdline"]):
            if any(str(self.root) in arg for arg in p.info["cmdline"] or []):
                p.kill()
        mounts = [line.split()[1] for line in Path("/proc/mounts").read_text().splitlines()]
        for m in sorted((m for m in mounts if m.startswith(str(self.root))), key=len, reverse=True):
            subprocess.run(["umount", "-l", m], capture_output=True)

    def stop(self) -> None:
        if self.proc and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self.proc.kill()


@pytest.fixture
def daemon(tmp_path_factory):
    if shutil.which("dockerd") is None or shutil.which("unshare") is None or os.getuid() != 0:
        _unavailable("a second dockerd needs the dockerd and unshare binaries and root")
    probe = subprocess.run(["docker", "image", "inspect", BASE], capture_output=True)
    if probe.returncode != 0:
        _unavailable(f"no {BASE} base image (scripts/make-offline-base.sh builds it offline)")
    root = tmp_path_factory.mktemp("dockerd")
    d = Daemon(root)
    d.start()
    try:
        save = subprocess.Popen(["docker", "save", BASE], stdout=subprocess.PIPE)
        d.docker("load", stdin=save.stdout)
        save.wait()
        yield d
    finally:
        if d.answers():
            d.docker("rm", "-f", *d.docker("ps", "-aq", check=False).stdout.decode().split(), check=False)
        d.stop()
        d.cleanup()


def sh_method(seconds: float) -> dict:
    """A method in a plain Debian container: waits, then writes a trajectory from the view's times.txt."""
    script = (
        f"echo start; sleep {seconds}; "
        "awk '{{print $2, $1 * 0.01, 0, 0, 0, 0, 0, 1}}' {times} > {out}; echo end"
    )
    return {"name": "external", "label": "sh", "params": {"argv": ["sh", "-c", script], "image": BASE}}


def test_a_dead_daemon_is_named_within_seconds_and_its_finished_container_is_collected(
    daemon, tmp_path, tiny_dataset, monkeypatch
):
    monkeypatch.setenv("DOCKER_HOST", daemon.host)
    spec = write_spec(
        tmp_path,
        tiny_dataset,
        [sh_method(4)],
        datasets=one_sequence(tiny_dataset),
        backend="docker",
        trials=2,
        lanes=1,
        timeout_s=600,
        retries=2,
    )
    killed_at, started = [], []

    def on_event(kind, run, lane, info):
        if kind == "started":
            started.append(run.key)
        if kind == "started" and len(started) == 2:  # during the second run

            def kill_soon():
                time.sleep(1.5)  # the container is running its `sleep`
                daemon.kill()
                killed_at.append(time.monotonic())

            threading.Thread(target=kill_soon, daemon=True).start()

    with pytest.raises(DaemonUnreachable) as err:
        run_campaign(load_spec(spec), on_event=on_event, log=lambda *a: None)
    noticed = time.monotonic() - killed_at[0]
    assert noticed < 15, f"noticed after {noticed:.0f} s"
    msg = str(err.value)
    assert "Docker daemon unreachable" in msg and daemon.host in msg and "run the same command" in msg
    first, second = (started[0].direction.value, 0), (started[1].direction.value, 0)
    rows = {(r["direction"], r["trial"]): r for r in ledger_rows(tmp_path / "results")}
    assert rows[first]["status"] == "done"
    assert rows[second]["status"] == "pending" and rows[second]["attempts"] == 1
    assert all(r["status"] in ("done", "pending") for r in rows.values())  # nothing charged, nothing infra
    assert all(r["failure"] is None for r in rows.values())
    first_done = Path(rows[first]["run_dir"])
    mtime = (first_done / "run.json").stat().st_mtime_ns

    time.sleep(5)  # the container completes without its daemon
    daemon.start()
    res = run_campaign(load_spec(spec), log=lambda *a: None)
    assert res.counts == {"pending": 0, "running": 0, "done": 4, "failed": 0}
    assert res.recovered["collected"] == 1
    rows = {(r["direction"], r["trial"]): r for r in ledger_rows(tmp_path / "results")}
    assert rows[second]["attempts"] == 1  # collected, not redone
    collected = json.loads((Path(rows[second]["run_dir"]) / "run.json").read_text())
    assert "finished while away" in collected["collected"] and collected["wall_s"] >= 4
    # the log holds what the daemon captured; what the method printed while the daemon was down is lost
    assert "start" in (Path(rows[second]["run_dir"]) / "log.txt").read_text()
    assert (first_done / "run.json").stat().st_mtime_ns == mtime
    assert daemon.docker("ps", "-aq").stdout.strip() == b""  # no container left behind
