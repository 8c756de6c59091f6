"""make bench: serve (one figure set, measured side by side with its baseline)."""

from __future__ import annotations

import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from bench.common import report


def bench_serve(tmp: Path, seconds: float = 30.0, rate: float = 20.0, viewers: int = 5) -> None:
    """`slamrun serve` (its own process, --interval 1) on a live 10,000-run campaign watched by `viewers` pages
    (server-sent events): a writer thread here finishes runs at `rate` runs/s as a 2-lane campaign writes its
    ledger. The server's CPU (over the watched period) and peak RSS (sampled at 10 Hz); the update latency, from
    the commit that made a finished count to the first event of each viewer showing it; and, side by side, one
    `slamrun status` read (read_figures) of the same ledger against the server's CPU per snapshot it sent."""
    import http.client
    import json
    import re
    import signal
    import threading

    import psutil

    from slamrun.engine.ledger import Ledger
    from slamrun.engine.plan import plan
    from slamrun.engine.session import read_figures
    from slamrun.engine.spec_file import validate_spec
    from slamrun.serve.snapshot import snapshot

    name = "live"
    print(f"slamrun serve: a 10,000-run campaign finishing {rate:.0f} runs/s, watched by {viewers} viewers (SSE)")
    folder = tmp / name
    raw = {
        "name": name,
        "results": str(folder),
        "trials": 10,
        "datasets": [
            {"name": "tum", "path": str(tmp / "nowhere"), "sequences": [f"sequence_{i:02d}" for i in range(1, 51)]}
        ],
        "methods": [{"name": "external", "label": f"m{i}", "params": {"argv": ["true", str(i)]}} for i in range(10)],
    }
    runs = plan(validate_spec(raw, base_dir=tmp, check_files=False))
    assert len(runs) == 10_000
    ledger = Ledger(folder / "ledger.sqlite")
    ledger.sync_plan(runs)
    ledger.set_meta("campaign", name)
    rng = np.random.default_rng(0)
    keys = iter(r.key.id for r in runs)
    lanes, before = 2, 4000  # 40 % finished when the viewers arrive
    started = time.time() - before / rate
    ledger.set_meta("eta", {"pending": len(runs), "lanes": lanes})
    me = psutil.Process()  # the bench's own process: alive, so the campaign shows as running
    session = {"pid": me.pid, "pid_start": me.create_time(), "started_at": started, "lanes": lanes, "ended_at": None}
    ledger.set_meta("session", session)

    def values(i: int, ended: float) -> tuple[str, dict]:
        wall = float(rng.uniform(0.08, 0.12))
        out = {"started_at": ended - wall, "ended_at": ended, "wall_s": wall, "run_dir": str(folder / "runs" / str(i))}
        if i % 20 == 19:  # one run in twenty lost, as a method loses track
            return "failed", {**out, "failure": "lost", "message": "tracking lost at frame 812", "exit_code": 0}
        ate = float(rng.lognormal(-2.0, 0.5))
        return "done", {**out, "eval_status": "ok", "ate_rmse": ate, "e_align": 3 * ate, "fps": 30.0, "n_poses": 1500}

    for i in range(before):
        ledger.finish(next(keys), *values(i, started + i / rate))
    running = [next(keys) for _ in range(lanes)]
    for key in running:
        ledger.mark_running(key, str(folder / "runs" / key))

    slamrun = str(Path(sys.executable).parent / "slamrun")
    argv = [slamrun, "serve", str(folder), "--host", "127.0.0.1", "--port", "0", "--interval", "1"]
    errors = tmp / "serve.stderr"  # a file, not a pipe nobody reads: a chatty server never blocks on it
    with open(errors, "w") as err:
        server = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=err, text=True)
    stop = threading.Event()
    threads: list[threading.Thread] = []
    try:
        proc = psutil.Process(server.pid)
        line = server.stdout.readline()
        m = re.search(r"at http://127\.0\.0\.1:(\d+)/", line)
        if m is None:
            raise RuntimeError(f"slamrun serve printed {line!r}, stderr: {errors.read_text()[-500:]!r}")
        port = int(m.group(1))
        peak_rss = proc.memory_info().rss
        seen: list[list[tuple[float, int, int]]] = [[] for _ in range(viewers)]  # (received, finished, body hash)
        sizes: list[int] = []
        ended: list[str] = [""] * viewers

        def viewer(v: int) -> None:
            conn = http.client.HTTPConnection("127.0.0.1", port, timeout=10)
            try:
                conn.request("GET", f"/c/{name}/events", headers={"Accept": "text/event-stream"})
                resp = conn.getresponse()
                assert resp.status == 200, resp.status
                event = ""
                while not stop.is_set():
                    text = resp.readline()
                    if not text:
                        ended[v] = "end of stream"
                        return
                    if text.startswith(b"event: "):
                        event = text[7:].strip().decode()
                    elif text.startswith(b"data: ") and event == "state":
                        at = time.monotonic()
                        finished = json.loads(text[6:])["progress"]["finished"]
                        seen[v].append((at, finished, hash(text)))
                        sizes.append(len(text))
            except (OSError, http.client.HTTPException, AssertionError) as exc:
                ended[v] = repr(exc)
            finally:
                conn.close()

        threads = [threading.Thread(target=viewer, args=(v,), daemon=True) for v in range(viewers)]
        for t in threads:
            t.start()
        deadline = time.monotonic() + 30
        while not all(seen) and time.monotonic() < deadline:  # every viewer has its first snapshot
            peak_rss = max(peak_rss, proc.memory_info().rss)
            time.sleep(0.1)
        assert all(seen), f"viewers without a first snapshot: {ended}"

        commits: dict[int, float] = {}  # finished count -> when the commit that made it returned

        def writer() -> None:
            t0, n = time.monotonic(), before
            i = 0
            while not stop.is_set() and time.monotonic() - t0 < seconds:
                wait = t0 + i / rate - time.monotonic()
                if wait > 0:
                    time.sleep(wait)
                key = running.pop(0)
                ledger.finish(key, *values(n, time.time()))
                n += 1
                commits[n] = time.monotonic()
                new = next(keys)
                ledger.mark_running(new, str(folder / "runs" / new))
                running.append(new)
                i += 1

        cpu0, w0 = sum(proc.cpu_times()[:2]), time.monotonic()
        first_event = [len(s) for s in seen]
        write = threading.Thread(target=writer, daemon=True)
        write.start()
        while write.is_alive():
            peak_rss = max(peak_rss, proc.memory_info().rss)
            time.sleep(0.1)
        last = max(commits)
        drain = time.monotonic() + 5  # the last count reaches every viewer
        while time.monotonic() < drain and not all(s and s[-1][1] >= last for s in seen):
            peak_rss = max(peak_rss, proc.memory_info().rss)
            time.sleep(0.1)
        cpu_s, watched = sum(proc.cpu_times()[:2]) - cpu0, time.monotonic() - w0
        sent = {h for s, k in zip(seen, first_event, strict=True) for _, _, h in s[k:]}

        latencies, missed = [], 0
        for count in range(before + 10, last + 1, 10):  # milestones: every 10th finished run
            for s in seen:
                at = next((t for t, f, _ in s if f >= count), None)
                if at is None:
                    missed += 1
                else:
                    latencies.append(at - commits[count])
        # the baseline: one `slamrun status` read of the same ledger, and the server's snapshot built here; CPU
        # seconds of this thread (the server's figure is CPU time too; the loaded machine's waits count in neither)
        status_reads, status_walls, snapshots = [], [], []
        for _ in range(5):
            t0, c0 = time.perf_counter(), time.thread_time()
            assert read_figures(folder).finished == last
            status_reads.append(time.thread_time() - c0)
            status_walls.append(time.perf_counter() - t0)
            c0 = time.thread_time()
            snapshot(folder, name)
            snapshots.append(time.thread_time() - c0)
        status_s = statistics.median(status_reads)

        t0 = time.monotonic()
        server.send_signal(signal.SIGTERM)  # with the viewers still connected, as browser tabs stay open
        try:
            rc = server.wait(timeout=10)
        except subprocess.TimeoutExpired:
            rc = None
        exit_s = time.monotonic() - t0
    finally:
        stop.set()
        if server.poll() is None:
            server.kill()
            server.wait()
        ledger.close()
    for t in threads:
        t.join(timeout=5)

    per_snapshot = cpu_s / max(len(sent), 1)
    lat_ms = np.array(latencies) * 1000
    report(f"runs finished while watched ({rate:.0f} runs/s, {watched:.0f} s)", f"{last - before}", "-")
    report("distinct snapshots sent (state events, any viewer)", f"{len(sent)}", "-")
    report("  size of one (JSON)", f"{statistics.median(sizes) / 1024:.0f} KB", "-")
    report(f"server CPU, {viewers} viewers, --interval 1", f"{100 * cpu_s / watched:.1f} % of a core", "< 25 %")
    report("server peak RSS", f"{peak_rss / 2**20:.0f} MB", "< 300 MB")
    if len(lat_ms):
        report(f"update latency, median ({len(lat_ms)} = viewers x milestones)", f"{np.median(lat_ms):.0f} ms", "< 2 s")
        report("update latency, 95th percentile", f"{np.percentile(lat_ms, 95):.0f} ms", "< 4 s")
    report("  milestones a viewer never saw", f"{missed}", "0")
    status_wall = f"{1000 * statistics.median(status_walls):.0f} ms wall"
    report("status read (read_figures, median of 5), CPU", f"{1000 * status_s:.0f} ms ({status_wall})", "-")
    snapshot_ms = 1000 * statistics.median(snapshots)
    report("snapshot() of the same ledger in this process, CPU", f"{snapshot_ms:.0f} ms", "-")
    report("server CPU per snapshot sent", f"{1000 * per_snapshot:.0f} ms", "-")
    report("  ratio per snapshot / status read", f"{per_snapshot / status_s:.2f}x", "< 3x")
    report("server ends on SIGTERM (viewers connected)", f"exit {rc} in {exit_s:.1f} s", "exit 0")
