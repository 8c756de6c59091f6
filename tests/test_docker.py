"""The container backends against real engines and real containers (no mocks): Docker's daemon, and podman
(no daemon; the same tests, the image exported from Docker and loaded into podman's store).

Skipped, with the reason shown, only where no engine can be reached; under CI (CI=true) a missing engine,
podman or base image is a failure, since .ci/run installs and starts them.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import sqlite3
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import pandas as pd
import pytest

from slamrun.backends.base import ExecRequest
from slamrun.datasets.cache import prepare
from slamrun.datasets.view import Direction, Profile
from slamrun.engine.campaign import run_campaign
from slamrun.engine.ledger import Ledger
from slamrun.engine.spec_file import load_spec
from slamrun.errors import InfraError
from tests.conftest import one_sequence, write_spec

IMAGE = "slamrun/reference_vo:latest"
IN_CI = os.environ.get("CI") == "true"
TEST_CAMPAIGNS = ("t", "killtest", "pytest-docker")  # the campaign names these tests label containers with


def _unavailable(reason: str):
    if IN_CI:
        pytest.fail(f"CI must run the Docker tests: {reason}")
    pytest.skip(reason=reason)


def engine_with_base():
    """The Docker API client, when an engine answers and has the Debian base image; skips (fails under CI)
    otherwise."""
    from slamrun.backends.docker import DockerBackend

    try:
        api = DockerBackend().client.api
    except InfraError as exc:
        _unavailable(f"no Docker engine: {exc}")
    if not api.images(name="debian:bookworm-slim"):
        _unavailable("no debian:bookworm-slim base image (scripts/make-offline-base.sh builds it offline)")
    return api


@pytest.fixture(scope="module", params=["docker", "podman"])
def backend(request):
    from slamrun.backends.this_machine import make_local_backend

    if request.param == "podman" and shutil.which("podman") is None:
        _unavailable("podman is not installed (Debian: apt-get install podman)")
    engine_with_base()  # the images are built with Docker in either case
    b = make_local_backend(request.param)
    try:
        b.check()
    except InfraError as exc:
        _unavailable(f"no {request.param} engine: {exc}")
    for name in TEST_CAMPAIGNS:  # containers an interrupted earlier test session left in this engine
        for old in b.client.containers.list(all=True, filters={"label": f"slamrun.campaign={name}"}):
            old.remove(force=True)
    yield b
    b.close()


def in_podman(tag: str) -> None:
    """`tag`, built by Docker, in podman's store (exported and loaded when podman lacks it or has an older one)."""
    from slamrun.backends.docker import DockerBackend
    from slamrun.images.export import export_image

    docker_id = DockerBackend().client.images.get(tag).id
    have = subprocess.run(["podman", "image", "inspect", "--format", "{{.Id}}", tag], capture_output=True, text=True)
    if have.returncode == 0 and docker_id.removeprefix("sha256:") == have.stdout.strip():
        return
    with tempfile.TemporaryDirectory() as tmp:
        path, _ = export_image(DockerBackend().client, tag, Path(tmp))
        subprocess.run(["podman", "load", "-q", "-i", str(path)], check=True, capture_output=True)


@pytest.fixture(scope="module")
def image(backend):
    """The reference VO image, built from slamrun/methods/reference_vo/image/Dockerfile (Docker's layer cache makes
    reruns fast)."""
    from slamrun.images.build import build

    build(["reference_vo"], log=lambda *a: None)
    if backend.name == "podman":
        in_podman(IMAGE)
    return IMAGE


def _request(tmp_path, view, argv, **kw) -> ExecRequest:
    work = tmp_path / "work"
    work.mkdir()
    return ExecRequest(
        argv=argv,
        workdir=work,
        view=view,
        log_path=tmp_path / "log.txt",
        resources_path=tmp_path / "resources.csv",
        image=kw.pop("image", IMAGE),
        timeout_s=kw.pop("timeout_s", 60),
        labels={"slamrun.campaign": "pytest-docker"},
        **kw,
    )


@pytest.fixture
def view(tmp_path, tiny_dataset):
    return prepare(tiny_dataset / "seq_a", Direction.forward, Profile.native, tmp_path / "cache")


def _no_containers(backend, campaign: str, results: Path | None = None) -> bool:
    """No container of `campaign` is left; with `results`, of that results folder only (another test suite on the
    same engine may be running a campaign of the same name)."""
    labels = [f"slamrun.campaign={campaign}"]
    if results is not None:
        labels.append(f"slamrun.results={Ledger(results / 'ledger.sqlite', read_only=True).meta('results_id')}")
    return not backend.client.containers.list(all=True, filters={"label": labels})


def _engine_process(backend):
    """The process that answers the backend's API: podman's service, or dockerd."""
    import psutil

    if backend.name == "podman":
        return psutil.Process(backend.service.proc.pid)
    return next(p for p in psutil.process_iter(["name"]) if p.info["name"] == "dockerd")


def test_the_engine_spends_no_core_while_a_run_waits(backend, image, tmp_path, view):
    """A run's container is watched without costing the method CPU: podman's API service answered slamrun's
    `wait` requests by polling flat out (containers/podman#18150), 1.2-1.3 cores of this 2-core machine for as
    long as a container ran, so a podman run's FPS and CPU figures were taken beside slamrun's own load (DSO at 2
    lanes ran 3 times slower than under Docker). The engine's CPU time while a container sleeps 4 s stays under a
    tenth of the wall time (Docker's and podman's measured: about 0.01)."""
    req = _request(tmp_path, view, ["python3", "-c", "import time; time.sleep(4)"])
    engine = _engine_process(backend)
    before, t0 = engine.cpu_times(), time.monotonic()
    res = backend.execute(req, threading.Event())
    after, wall = engine.cpu_times(), time.monotonic() - t0
    assert res.exit_code == 0 and not res.timed_out
    busy = (after.user + after.system) - (before.user + before.system)
    assert busy < 0.1 * wall, f"{backend.name}'s engine used {busy:.2f} s of CPU in a {wall:.1f} s run"


def test_hang_is_killed_at_timeout(backend, image, tmp_path, view):
    req = _request(
        tmp_path, view, ["python3", "-c", "import time; print('start', flush=True); time.sleep(600)"], timeout_s=3
    )
    t0 = time.monotonic()
    res = backend.execute(req, threading.Event())
    assert res.timed_out and time.monotonic() - t0 < 30
    assert "start" in req.log_path.read_text()
    assert _no_containers(backend, "pytest-docker")


def test_nonzero_exit_and_contract(backend, image, tmp_path, view):
    script = (
        "import os, socket, sys\n"
        "print('uid', os.getuid(), 'data', sorted(os.listdir('/data'))[:3], flush=True)\n"
        "open('/work/out.txt', 'w').write('ok')\n"
        "open('/work/masks/m.txt', 'w').write('ok')\n"
        "try:\n    open('/data/x', 'w')\nexcept OSError:\n    print('data is read-only')\n"
        "try:\n    socket.create_connection(('127.0.0.1', 9), timeout=1)\nexcept OSError as e:\n    print('net', e)\n"
        "print('nproc', len(os.sched_getaffinity(0)))\n"
        "sys.exit(3)\n"
    )
    req = _request(tmp_path, view, ["python3", "-c", script], cpus=(0,))
    (req.workdir / "masks").mkdir()  # a folder the adapter wrote (DynaSLAM's mask cache): the run's user writes in it
    res = backend.execute(req, threading.Event())
    log = req.log_path.read_text()
    assert res.exit_code == 3 and not res.timed_out and not res.oom
    assert "uid 1000" in log or f"uid {os.getuid()}" in log  # a non-root user
    assert "data is read-only" in log and "camera.txt" in log and "nproc 1" in log
    assert (req.workdir / "out.txt").read_text() == "ok" and (req.workdir / "masks" / "m.txt").read_text() == "ok"


def test_memory_limit_is_oom(backend, image, tmp_path, view, monkeypatch):
    """An out-of-memory run is said so, and leaves nothing in the folder slamrun was started from (podman's conmon
    writes an `oom` marker into its working directory, which it inherits from the API service)."""
    cwd = tmp_path / "started-here"
    cwd.mkdir()
    monkeypatch.chdir(cwd)
    from slamrun.backends.this_machine import make_local_backend

    started_here = make_local_backend(backend.name)  # its engine's helpers (podman's service) start in `cwd`
    req = _request(tmp_path, view, ["python3", "-c", "x = bytearray(600 * 2**20); print(len(x))"], memory_mb=100)
    try:
        res = started_here.execute(req, threading.Event())
    finally:
        started_here.close()
    assert res.oom and res.exit_code != 0
    assert sorted(p.name for p in cwd.iterdir()) == []


def test_log_flood_is_capped(backend, image, tmp_path, view):
    flood = "import sys\nfor i in range(200000): sys.stdout.write('%08d' % i + 'x' * 92 + '\\n')\nprint('END')"
    req = _request(tmp_path, view, ["python3", "-c", flood], log_cap_bytes=2**20)
    res = backend.execute(req, threading.Event())
    text = req.log_path.read_text()
    assert res.exit_code == 0 and res.log_truncated
    assert req.log_path.stat().st_size < 1.1 * 2**20 and text.rstrip().endswith("END") and "log capped" in text


def test_a_slowly_read_log_is_read_to_its_end(backend, image, tmp_path, view, monkeypatch):
    """After the container exits its log is read on while bytes still come, however slowly (on a loaded machine a
    flooded log came for more than the 10 s slamrun waited, and its end was cut). The engine's stream is slowed here
    to 8 kB/s: 100 kB take 12.5 s."""
    read = type(backend)._pump_logs

    class Slow:
        def __init__(self, log):
            self.log = log

        def write(self, data: bytes) -> None:
            time.sleep(len(data) / 8000)
            self.log.write(data)

    monkeypatch.setattr(backend, "_pump_logs", lambda container, log, follow=True: read(container, Slow(log), follow))
    script = "for i in range(100): print('%05d' % i + 'x' * 994)\nprint('END')"
    req = _request(tmp_path, view, ["python3", "-c", script])
    res = backend.execute(req, threading.Event())
    text = req.log_path.read_text()
    assert res.exit_code == 0 and not res.log_truncated
    assert text.count("x" * 994) == 100 and text.rstrip().endswith("END"), text[-300:]


@pytest.mark.parametrize("stream", ["ends early", "hangs"])
def test_a_log_stream_cut_short_is_completed_from_the_stored_log(backend, image, tmp_path, view, monkeypatch, stream):
    """The engine's log stream can end before the last lines (Docker under load: CI's flood test read 42,521 of
    200,000 lines) or hang after the exit (docker/docker-py#3084): the log is still whole, with no line twice."""
    read = type(backend)._pump_logs
    release = threading.Event()

    class CutShort:
        def __init__(self, sink):
            self.sink, self.seen = sink, 0

        def write(self, data: bytes) -> None:
            if self.seen >= 5000:
                if stream == "ends early":
                    raise ConnectionError("the stream ended")  # _pump_logs ends as at the stream's end
                release.wait()
            self.sink.write(data)
            self.seen += len(data)

    monkeypatch.setattr(backend, "_pump_logs", lambda c, log, follow=True: read(c, CutShort(log), follow))
    script = "for i in range(100): print('%05d' % i + 'x' * 994)\nprint('END')"
    req = _request(tmp_path, view, ["python3", "-c", script])
    try:
        res = backend.execute(req, threading.Event())
    finally:
        release.set()
    lines = req.log_path.read_text().splitlines()
    assert res.exit_code == 0 and lines == [f"{i:05d}" + "x" * 994 for i in range(100)] + ["END"]


def test_missing_image_is_infra(backend, tmp_path, view):
    with pytest.raises(InfraError, match="make images" if backend.name == "docker" else "podman load -i"):
        backend.check({"nonexistent": "slamrun/does-not-exist:latest"})
    req = _request(tmp_path, view, ["true"], image="slamrun/does-not-exist:latest")
    with pytest.raises(InfraError, match="missing"):
        backend.execute(req, threading.Event())


def test_unreachable_daemon_is_reported_before_runs(tmp_path, monkeypatch):
    from slamrun.backends.docker import DockerBackend

    monkeypatch.setenv("DOCKER_HOST", f"unix://{tmp_path}/no-daemon.sock")
    with pytest.raises(InfraError, match="Docker daemon unreachable at"):
        DockerBackend().check()


@pytest.fixture(scope="module")
def vo_dataset(tmp_path_factory):
    from slamrun.datasets.make_synthetic import generate

    root = tmp_path_factory.mktemp("docker_data")
    generate(root / "seq_a", frames=200, seed=3, size=(640, 480))
    return root


def test_campaign_with_reference_vo_image(backend, image, tmp_path, vo_dataset):
    spec = write_spec(
        tmp_path,
        vo_dataset,
        [{"name": "reference_vo"}],
        backend=backend.name,
        memory_limit_mb=1500,
        timeout_s=300,
        datasets=one_sequence(vo_dataset),
    )
    res = run_campaign(load_spec(spec), log=lambda *a: None)
    df = pd.read_csv(res.results_csv)
    assert len(df) == 2 and set(df.direction) == {"forward", "backward"}
    assert (df.status == "done").all() and (df.eval_status == "ok").all(), df.message.tolist()
    assert (df.cpu_mean_pct > 10).all() and (df.ram_peak_mb > 20).all() and (df.fps > 0).all()
    assert df.gpu_mem_peak_mb.isna().all()
    # the container's threads' wait for a CPU, read from this machine's /proc (its processes found by their cgroup)
    assert df.cpu_wait_pct.notna().all() and (df.cpu_wait_pct >= 0).all(), df.cpu_wait_pct.tolist()
    series = pd.read_csv(Path(df.run_dir[0]) / "resources.csv")
    # sampled through the run (how many samples depends on the engine's load: a stats call can take a second; the
    # schedule, 2 Hz from the first sample, is checked on a fake clock in tests/test_monitor_rate.py)
    assert len(series) >= 3 and series.t_s.is_monotonic_increasing and series.t_s.iloc[-1] <= df.wall_s[0]
    assert _no_containers(backend, "t", tmp_path / "results")


def _running_keys(results: Path) -> set[str]:
    """The runs the ledger at `results` holds as running (read-only: the campaign may be writing it)."""
    path = results / "ledger.sqlite"
    if not path.exists():
        return set()
    db = sqlite3.connect(f"file:{path}?mode=ro", uri=True, timeout=30)
    try:
        return {key for (key,) in db.execute("SELECT key FROM runs WHERE status = 'running'")}
    except sqlite3.OperationalError:  # the table is not created yet
        return set()
    finally:
        db.close()


def test_kill_9_leaves_no_container_and_redoes_runs(backend, image, tmp_path, vo_dataset):
    labels = {"label": "slamrun.campaign=killtest"}
    spec = write_spec(
        tmp_path,
        vo_dataset,
        [{"name": "reference_vo"}],
        backend=backend.name,
        timeout_s=300,
        trials=1,
        datasets=one_sequence(vo_dataset),
        name="killtest",
    )
    proc = subprocess.Popen(
        [sys.executable, "-m", "slamrun.cli", "campaign", str(spec)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    # Killed while a container runs for a run the ledger holds as running: found by the container's labels
    # first (the engine's answer takes longest), then the ledger, then at once SIGKILL.
    interrupted: set[str] = set()
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not interrupted and proc.poll() is None:
        running = {c.labels.get("slamrun.run") for c in backend.client.containers.list(filters=labels)}
        interrupted = running & _running_keys(tmp_path / "results")
        if interrupted:
            os.kill(proc.pid, signal.SIGKILL)
        else:
            time.sleep(0.1)
    proc.wait()
    assert interrupted, "the campaign ended, or no run started within 120 s, before it could be killed mid-run"
    at_kill = _running_keys(tmp_path / "results")  # what the killed process left
    assert interrupted <= at_kill
    assert backend.client.containers.list(all=True, filters=labels)  # the orphan is still there
    res = run_campaign(load_spec(spec), log=lambda *a: None)
    assert res.counts["done"] == 2
    assert res.recovered["requeued"] + res.recovered["imported"] == len(at_kill), res.recovered
    assert _no_containers(backend, "killtest")
    df = pd.read_csv(res.results_csv)
    assert (df.status == "done").all() and (df.attempts >= 1).all()
    with contextlib.closing(sqlite3.connect(tmp_path / "results" / "ledger.sqlite")) as db:
        attempts = dict(db.execute("SELECT key, attempts FROM runs"))
    # each interrupted run was redone once, or its container, which went on running, finished before the
    # restart looked and was collected as its attempt
    assert all(attempts[key] in (1, 2) for key in interrupted), attempts
    assert sum(attempts[key] == 1 for key in interrupted) <= res.recovered.get("collected", 0), res.recovered


def test_dask_workers_check_their_own_docker_images(backend, image, tmp_path):
    """With the Dask engine, each worker checks its own engine (Docker's daemon, podman) and images before any run."""
    pytest.importorskip("distributed")
    import socket

    from slamrun.backends.dask import DaskBackend

    dask = DaskBackend(backend.name, "local", tmp_path, local_workers=1)
    try:
        dask.check({"reference_vo": image})  # present on this machine's daemon: fine
        with pytest.raises(InfraError) as err:
            dask.check({"nonexistent": "slamrun/does-not-exist:latest"})
        assert socket.gethostname() in str(err.value)
        assert ("make images" if backend.name == "docker" else "podman load -i") in str(err.value)
    finally:
        dask.close()


def test_podmans_api_service_ends_with_a_runner_killed_by_sigkill():
    if shutil.which("podman") is None:
        _unavailable("podman is not installed (Debian: apt-get install podman)")
    script = (
        "import sys, time\n"
        "from slamrun.backends.podman import PodmanBackend\n"
        "b = PodmanBackend(); b.client.ping()\n"
        "print(b.service.proc.pid, flush=True)\n"
        "time.sleep(600)\n"
    )
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    service = int(proc.stdout.readline())
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    deadline = time.monotonic() + 15
    while time.monotonic() < deadline:
        try:
            os.kill(service, 0)
        except ProcessLookupError:
            break
        with contextlib.suppress(ChildProcessError):
            os.waitpid(service, os.WNOHANG)  # not our child: reaped by init; this only avoids a zombie here
        time.sleep(0.1)
    state = Path(f"/proc/{service}/stat").read_text().split()[2] if Path(f"/proc/{service}").exists() else "gone"
    assert state in ("gone", "Z"), f"podman system service {service} still runs ({state})"


def test_leftovers_are_this_results_folders_only(backend, image):
    """The same campaign started with another --results once removed the first one's running container (found by
    the campaign's label alone): leftovers are the containers of this campaign *and* results folder, and those of
    the campaign that carry no results label (left by a slamrun before the label)."""
    made = {}
    for name, labels in (
        ("ours", {"slamrun.campaign": "pytest-docker", "slamrun.results": "aaaa"}),
        ("theirs", {"slamrun.campaign": "pytest-docker", "slamrun.results": "bbbb"}),
        ("older", {"slamrun.campaign": "pytest-docker"}),
        ("other campaign", {"slamrun.campaign": "t", "slamrun.results": "aaaa"}),
    ):
        made[name] = backend.client.containers.create(image, ["sleep", "60"], labels=labels, network_mode="none")
    try:
        found = {c.id for c in backend.leftovers("pytest-docker", "aaaa")}
        assert found == {made["ours"].id, made["older"].id}
        found = {c.id for c in backend.leftovers("pytest-docker", "bbbb")}
        assert found == {made["theirs"].id, made["older"].id}
    finally:
        for c in made.values():
            c.remove(force=True)
