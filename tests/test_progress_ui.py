"""What a researcher reads while a batch runs: the live view under a real pseudo-terminal, plain progress
lines, the dry run, `status --watch` and `--json` from a second process, the failed-run list."""

from __future__ import annotations

import json
import os
import pty
import re
import select
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from slamrun.engine.progress import Tracker, eta, figures
from tests.conftest import fake_method, write_spec
from tests.test_campaign import ledger_rows

ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]|\x1b\][^\x07]*\x07|\r")


def run_in_pty(args: list[str], timeout: float = 240) -> tuple[int, str]:
    """Run the CLI with a pseudo-terminal as its stdout (rich sees a terminal); returns (code, text)."""
    master, slave = pty.openpty()
    env = {**os.environ, "COLUMNS": "200", "LINES": "50", "TERM": "xterm"}
    proc = subprocess.Popen(
        [sys.executable, "-m", "slamrun.cli", *args], stdin=subprocess.DEVNULL, stdout=slave, stderr=slave, env=env
    )
    os.close(slave)
    chunks, deadline = [], time.monotonic() + timeout
    while time.monotonic() < deadline:
        ready, _, _ = select.select([master], [], [], 0.5)
        if ready:
            try:
                data = os.read(master, 65536)
            except OSError:
                break
            if not data:
                break
            chunks.append(data)
        elif proc.poll() is not None:
            break
    os.close(master)
    return proc.wait(timeout=30), ANSI.sub("", b"".join(chunks).decode(errors="replace"))


def snapshot(folder: Path) -> dict[str, tuple[int, int]]:
    if not folder.exists():
        return {}
    return {str(p.relative_to(folder)): (p.stat().st_size, p.stat().st_mtime_ns) for p in folder.rglob("*")}


# ------------------------------------------------------------ the figures


def test_eta_is_the_median_wall_time_per_method_and_sequence_times_runs_left_over_lanes():
    a, b, c = ("a", "d/s1"), ("b", "d/s1"), ("c", "d/s1")
    walls = {a: [10.0, 12.0, 100.0], b: [4.0]}
    assert eta({a: 3, b: 5}, walls, lanes=2) == ((3 * 12.0 + 5 * 4.0) / 2, "measured")
    seconds, basis = eta({a: 1, c: 2}, walls, lanes=1)  # c has no finished run: the median of all
    assert basis == "partly estimated" and seconds == 12.0 + 2 * 11.0
    assert eta({a: 2}, {}, lanes=1) == (None, "unknown")
    assert eta({a: 0}, walls, lanes=1) == (0.0, "-")


def test_eta_tells_a_long_sequence_from_a_short_one_of_the_same_method():
    """The study's sequences run from 40 s to 10 min: a method's median over all of them would say the same
    for each; per sequence, the runs left on the long one count as long."""
    short, long_ = ("dso", "tum-mono/seq_01"), ("dso", "tum-mono/seq_02")
    walls = {short: [40.0, 41.0, 39.0, 40.0, 40.0], long_: [600.0]}
    assert eta({long_: 9}, walls, lanes=1) == (9 * 600.0, "measured")  # the method's median (40 s) says 360 s
    seconds, basis = eta({("dso", "tum-mono/seq_03"): 2}, walls, lanes=1)  # not yet run: the method's median
    assert (seconds, basis) == (2 * 40.0, "partly estimated")


def test_the_eta_does_not_jump_when_a_slow_methods_first_run_ends():
    """A method with no finished run borrowed the others' pace (4 s) until its first run ended 40 s later, and the
    ETA went from about a minute to several between two readings (a campaign: 1 min 16 s, then 8 min 44 s). Its
    running run now shows its pace as it goes, and a running run counts for what it has still to go."""

    def row(key, label, state, wall=None, started=None):
        return {"key": key, "method": label, "dataset": "d", "sequence": "s", "direction": "forward"} | {
            "status": state, "failure": None, "wall_s": wall, "started_at": started
        }  # fmt: skip

    rows = [row(f"f{i}", "fast", "done", 4.0) for i in range(4)]
    rows += [row("s0", "slow", "running", started=10.0)] + [row(f"s{i}", "slow", "pending") for i in range(1, 6)]
    tracker = Tracker(rows, {"lanes": 1, "started_at": 0.0})
    before = tracker.figures(now=49.9).eta_s
    tracker.update("s0", status="done", wall_s=40.0)
    after = tracker.figures(now=50.0).eta_s
    assert after == pytest.approx(5 * 40.0)
    assert before == pytest.approx(6 * 39.9 - 39.9)  # its run so far: at least 39.9 s a run, 39.9 s of it gone
    # measured: a run 6 s into a group of 10 s runs has 4 s to go
    rows = [row("a", "m", "done", 10.0), row("b", "m", "running", started=100.0), row("c", "m", "pending")]
    assert figures(rows, {"lanes": 1}, now=106.0).eta_s == pytest.approx(4.0 + 10.0)


def test_the_tracker_and_figures_agree_per_sequence():
    rows = [
        {"key": f"k{i}", "method": "m", "dataset": "d", "sequence": seq, "direction": "forward", "status": state}
        | {"failure": None, "wall_s": wall, "started_at": 100.0 + i}
        for i, (seq, state, wall) in enumerate(
            [("s1", "done", 10.0), ("s1", "pending", None), ("s2", "done", 50.0), ("s2", "pending", None)]
        )
    ]
    session = {"started_at": 100.0, "lanes": 1}
    tracker = Tracker(rows, session)
    assert tracker.figures(now=200.0).eta_s == figures(rows, session, now=200.0).eta_s
    tracker.update("k1", status="done", wall_s=12.0, started_at=150.0)
    rows[1] |= {"status": "done", "wall_s": 12.0, "started_at": 150.0}
    assert tracker.figures(now=200.0) == figures(rows, session, now=200.0)
    overhead = (1 * 100.0 - (10.0 + 50.0 + 12.0)) / 3  # the lane's time per run beyond the runs' own
    assert tracker.figures(now=200.0).eta_s == pytest.approx(50.0 + overhead)  # s2's run left, at s2's pace


def test_figures_count_infra_apart_and_measure_lane_occupancy():
    rows = [
        {"method": "m", "direction": "forward", "status": "done", "failure": None, "wall_s": 10.0}
        | {"started_at": 100.0},
        {"method": "m", "direction": "forward", "status": "failed", "failure": "lost", "wall_s": 6.0}
        | {"started_at": 111},
        {"method": "m", "direction": "backward", "status": "failed", "failure": "infra", "wall_s": None}
        | {"started_at": 1},
        {
            "method": "m",
            "direction": "backward",
            "status": "pending",
            "failure": None,
            "wall_s": None,
            "started_at": None,
        },
    ]
    f = figures(rows, {"started_at": 100.0, "lanes": 2, "ended_at": None}, now=120.0, campaign="c")
    assert (f.total, f.done, f.failed, f.infra, f.pending, f.finished) == (4, 1, 1, 1, 1, 3)
    assert f.failures == {"lost": 1}
    assert f.occupancy == pytest.approx(16.0 / (2 * 20.0))
    assert f.eta_s == pytest.approx(2 * 8.0 / 2)  # pending + infra (retried), median of 10 and 6
    backward = next(g for g in f.per_group if g["direction"] == "backward")
    assert backward["infra"] == 1 and backward["success_pct"] is None


# ------------------------------------------------------------ the live view on a terminal


def test_live_view_total_eta_resume_and_failed_runs(tmp_path, tiny_dataset):
    crash = fake_method("crash", label="crasher")
    crash["trials"] = 1
    spec = write_spec(tmp_path, tiny_dataset, [fake_method(sleep=1.0), crash], trials=2, lanes=1, report=False)
    code, out = run_in_pty(["campaign", str(spec)])
    assert code == 0, out[-3000:]
    assert "0/12" in out  # the total is known before the first run ends
    before_first = out[: out.index("1/12")]
    assert "ETA ?" in before_first
    after = out[out.index("1/12") :]
    assert re.search(r"ETA \d+ (s|min)", after), after[:2000]
    assert "lane 0:" in out  # what the lane runs now
    assert "t: failed runs (4)" in out  # the failed-run list, titled with the campaign's name
    assert out.count("log.txt") >= 4 and "crashed" in out
    assert "t: per method" in out

    # resume with more trials: the runs of the first session count as done from the start
    raw = yaml.safe_load(spec.read_text())
    raw["trials"] = 3
    spec.write_text(yaml.safe_dump(raw))
    code, out = run_in_pty(["campaign", str(spec)])
    assert code == 0, out[-3000:]
    assert "12/16" in out and "0/16" not in out


def test_plain_lines_carry_the_same_figures(tmp_path, tiny_dataset):
    """The headline every few runs, and each run's line with its main figure whatever the dataset's metrics:
    TUM-Mono's e_align, EuRoC's ATE RMSE (it showed none for an ATE dataset)."""
    from slamrun.datasets.make_synthetic import generate

    euroc = generate(tmp_path / "euroc" / "V1_tiny", frames=40, seed=1, size=(160, 120), layout="euroc")
    datasets = [
        {"name": "tum", "path": str(tiny_dataset), "sequences": ["seq_a", "seq_b"]},
        {"name": "euroc", "path": str(euroc.parent), "sequences": [euroc.name], "layout": "euroc"},
    ]
    spec = write_spec(tmp_path, tiny_dataset, [fake_method()], datasets=datasets, trials=2, lanes=1, report=False)
    proc = subprocess.run(
        [sys.executable, "-m", "slamrun.cli", "campaign", str(spec)], capture_output=True, text=True, timeout=240
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("progress:")]
    assert lines and "12/12 finished" in lines[-1] and "done 12" in lines[-1]
    assert any("ETA" in ln for ln in lines[:-1])
    runs = [ln for ln in proc.stdout.splitlines() if ln.startswith("[lane ")]
    assert len(runs) == 12, proc.stdout
    for ln in runs:
        figure = r" ate_rmse=[0-9.e+-]+ m$" if "/V1_tiny@" in ln else r" e_align=[0-9.e+-]+$"
        assert re.search(r": done \(ok\)" + figure, ln), ln


# ------------------------------------------------------------ the dry run


def _dry(capsys, spec: Path, tmp_path: Path) -> str:
    from slamrun.cli import main

    before = snapshot(tmp_path)
    assert main(["campaign", str(spec), "--dry-run"]) == 0
    assert snapshot(tmp_path) == before  # nothing written, not even a lock, a ledger or a view
    return capsys.readouterr().out


def _counts(out: str) -> dict[tuple[str, str], list[int]]:
    rows = {}
    for line in out.splitlines():
        cells = [c.strip() for c in line.strip("│ ").split("│")]
        if len(cells) == 7 and cells[1] in ("forward", "backward"):
            rows[(cells[0], cells[1])] = [int(c) for c in cells[2:]]
    return rows


def test_dry_run_counts_are_exact(tmp_path, tiny_dataset, capsys):
    from slamrun.engine.campaign import run_campaign
    from slamrun.engine.spec_file import load_spec

    spec = write_spec(tmp_path, tiny_dataset, [fake_method(label="m")], trials=2, lanes=1, report=False)
    out = _dry(capsys, spec, tmp_path)  # new
    assert _counts(out) == {("m", "backward"): [4, 4, 0, 0, 0], ("m", "forward"): [4, 4, 0, 0, 0]}
    assert "8 run(s) to run of 8" in out and "4 view(s) to prepare" in out and "unknown" in out

    stop_after = []

    def on_event(kind, run, lane, info):
        if kind == "finished":
            stop_after.append(run)
            if len(stop_after) == 3:
                sched_ref[0].request_stop()

    sched_ref = []
    run_campaign(load_spec(spec), on_event=on_event, scheduler_hook=sched_ref.append, log=lambda *a: None)
    out = _dry(capsys, spec, tmp_path)  # half-finished (the run in flight at the stop finished too)
    done = sum(r["status"] == "done" for r in ledger_rows(tmp_path / "results"))
    assert 3 <= done < 8
    counts = _counts(out)
    assert sum(c[3] for c in counts.values()) == done and sum(c[1] for c in counts.values()) == 0
    assert sum(c[2] for c in counts.values()) == 8 - done
    assert f"{8 - done} run(s) to run of 8 ({done} done" in out
    assert re.search(r"estimated duration: \d+ s on 1 lane", out)

    run_campaign(load_spec(spec), log=lambda *a: None)
    out = _dry(capsys, spec, tmp_path)  # finished
    assert _counts(out) == {("m", "backward"): [4, 0, 0, 4, 0], ("m", "forward"): [4, 0, 0, 4, 0]}
    assert "0 run(s) to run of 8 (8 done" in out and "every view it needs is prepared" in out


# ------------------------------------------------------------ status from a second terminal


def test_status_watch_and_json_while_a_campaign_runs(tmp_path, tiny_dataset):
    spec = write_spec(tmp_path, tiny_dataset, [fake_method(sleep=1.5)], trials=2, lanes=1, report=False)
    results = tmp_path / "results"
    campaign = subprocess.Popen(
        [sys.executable, "-m", "slamrun.cli", "campaign", str(spec)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE
    )
    try:
        deadline = time.monotonic() + 60
        while not (results / "ledger.sqlite").exists() and time.monotonic() < deadline:
            time.sleep(0.2)
        seen = []
        while time.monotonic() < deadline:
            res = subprocess.run(
                [sys.executable, "-m", "slamrun.cli", "status", str(results), "--json"], capture_output=True, text=True
            )
            assert res.returncode == 0, res.stderr
            f = json.loads(res.stdout)
            seen.append(f)
            if f["finished"] >= 2:
                break
            time.sleep(0.5)
        assert seen[-1]["active"] and seen[-1]["total"] == 8 and seen[-1]["eta_s"] is not None
        assert seen[-1]["campaign"] == "t"
        code, out = run_in_pty(["status", str(results), "--watch", "--interval", "0.5"], timeout=120)
        assert code == 0
        assert "8/8" in out and "the campaign is not running" in out  # refreshed until the end
        assert re.search(r"[1-7]/8", out)  # and in between
    finally:
        campaign.wait(timeout=120)
    assert campaign.returncode == 0, campaign.stderr.read()
    final = json.loads(
        subprocess.run(
            [sys.executable, "-m", "slamrun.cli", "status", str(results), "--json"], capture_output=True, text=True
        ).stdout
    )
    assert final["done"] == 8 and not final["active"] and final["occupancy"] > 0.5


def test_every_argument_has_help_and_there_is_a_version():
    from slamrun.cli import _parser

    def check(parser, name: str) -> None:
        for action in parser._actions:
            if action.__class__.__name__ == "_SubParsersAction":
                for sub_name, sub in action.choices.items():
                    check(sub, f"{name} {sub_name}")
            elif action.dest != "help":
                assert action.help, f"{name}: {action.dest} has no help line"

    check(_parser(), "slamrun")
    res = subprocess.run([sys.executable, "-m", "slamrun.cli", "--version"], capture_output=True, text=True)
    assert res.returncode == 0 and res.stdout.startswith("slamrun ")


def test_the_tracker_equals_the_figures_of_the_same_rows_after_every_change():
    """The live view's figures are kept from events at a constant cost per run (slamrun.engine.progress.Tracker):
    after any sequence of changes they equal the figures computed from the ledger's rows."""
    import random

    from slamrun.engine.progress import Tracker, figures

    rng = random.Random(3)
    rows = [
        {
            "key": f"k{i}",
            "method": f"m{i % 3}",
            "direction": ("forward", "backward")[i % 2],
            "status": "pending",
            "failure": None,
            "wall_s": None,
            "started_at": None,
        }
        for i in range(300)
    ]
    session = {"lanes": 2, "started_at": 1000.0}
    tracker = Tracker(rows, session, "c")
    by_key = {r["key"]: r for r in rows}
    for step in range(2000):
        r = by_key[f"k{rng.randrange(300)}"]
        change = rng.choice(["start", "done", "fail", "infra", "requeue"])
        if change == "start":
            upd = {"status": "running", "started_at": 1000.0 + step}
        elif change == "done":
            upd = {"status": "done", "failure": None, "wall_s": rng.uniform(0.5, 3.0)}
        elif change == "fail":
            upd = {"status": "failed", "failure": rng.choice(["lost", "crashed", "timeout"]), "wall_s": 1.0}
        elif change == "infra":
            upd = {"status": "failed", "failure": "infra", "wall_s": None}
        else:
            upd = {"status": "pending"}
        r.update(upd)
        if upd["status"] == "pending":
            r["failure"] = None
        tracker.update(r["key"], **upd)
        if step % 97 == 0 or step == 1999:
            mine, theirs = tracker.figures(now=5000.0).to_dict(), figures(rows, session, 5000.0, "c").to_dict()
            for k in ("occupancy", "eta_s"):  # sums in another order: equal to rounding
                a, b = mine.pop(k), theirs.pop(k)
                assert (a is None and b is None) or a == pytest.approx(b, rel=1e-12), (step, k)
            assert mine == theirs, step


def test_the_eta_counts_the_runners_own_time_per_run():
    """Runs of 0.1 s that take 0.5 s of a lane each (starting, collecting): the estimate uses 0.5 s a run, not 0.1."""
    from slamrun.engine.progress import figures

    rows = [
        {"key": f"k{i}", "method": "m", "direction": "forward", "status": "done", "failure": None, "wall_s": 0.1,
         "started_at": 100.0 + 0.5 * i}
        for i in range(100)
    ] + [
        {"key": f"p{i}", "method": "m", "direction": "forward", "status": "pending", "failure": None, "wall_s": None,
         "started_at": None}
        for i in range(900)
    ]  # fmt: skip
    f = figures(rows, {"lanes": 1, "started_at": 100.0}, now=150.0)
    assert f.eta_s == pytest.approx(900 * 0.5)
    assert f.occupancy == pytest.approx(10 / 50)


def test_wall_times_give_the_medians_of_the_runs_they_hold_after_adds_and_removes():
    """The ETA's medians are read from lists kept sorted (constant cost per finished run at the study's scale):
    per group, per method over its groups, and overall, they equal statistics.median of the same wall times."""
    import random
    import statistics

    from slamrun.engine.progress import WallTimes

    rng = random.Random(7)
    groups = [(m, f"d/s{s}") for m in ("a", "b") for s in range(3)]
    held: dict = {g: [] for g in groups}
    times = WallTimes()
    for step in range(3000):
        g = rng.choice(groups)
        if held[g] and rng.random() < 0.4:
            w = rng.choice(held[g])
            held[g].remove(w)
            times.remove(g, w)
        else:
            w = round(rng.uniform(0.1, 9.0), 1)  # repeated values too
            held[g].append(w)
            times.add(g, w)
        if step % 50 == 0:
            every = [w for ws in held.values() for w in ws]
            for group in groups:
                mine = [w for (m, _), ws in held.items() if m == group[0] for w in ws]
                want = held[group] or mine or every
                if want:
                    assert times.typical(group) == statistics.median(want), (step, group)
    assert bool(times) == any(held.values())


def test_status_reads_only_the_columns_the_figures_use(tmp_path):
    """`slamrun status` reads the progress columns, not whole rows; the figures are the same."""
    from slamrun.engine.ledger import Ledger
    from slamrun.engine.progress import Tracker

    ledger = Ledger(tmp_path / "ledger.sqlite")
    rows = [
        {"key": f"k{i:03d}", "method": "m", "method_name": "m", "dataset": "d", "sequence": f"s{i % 3}"}
        | {"direction": "forward", "trial": i, "settings": "", "status": "done", "wall_s": 1.0 + i % 5}
        | {"started_at": 10.0 + i, "e_align": 0.01, "failure": None}
        for i in range(40)
    ]
    ledger.insert_finished(rows)
    full, narrow = ledger.rows(), ledger.progress_rows()
    ledger.close()
    assert [set(r) for r in narrow] == [set(Ledger.PROGRESS_COLUMNS)] * 40
    assert narrow == [{k: r[k] for k in Ledger.PROGRESS_COLUMNS} for r in full]
    session = {"lanes": 2, "started_at": 10.0}
    assert Tracker(narrow, session).figures(100.0) == Tracker(full, session).figures(100.0)
