"""Ways a campaign could lose work, blame the wrong party or leave processes behind; each with real processes.

(The Docker daemon dying mid-run is in test_docker_daemon.py.)"""

from __future__ import annotations

import json
import shutil
import time
from pathlib import Path

import numpy as np
import pandas as pd
import psutil
import pytest

from slamrun.analysis.load import evaluated
from slamrun.analysis.summary import method_summary
from slamrun.datasets.make_synthetic import generate
from slamrun.engine.campaign import run_campaign
from slamrun.engine.spec_file import load_spec
from slamrun.errors import DatasetError, SlamRunError
from tests.conftest import fake_method, one_sequence, write_spec
from tests.test_campaign import ledger_rows


def campaign(spec_path: Path, **kw):
    return run_campaign(load_spec(spec_path), log=kw.pop("log", lambda *a: None), **kw)


def folder_state(results: Path) -> dict[str, int]:
    """Every file under runs/ with its modification time (to prove nothing was rewritten)."""
    return {str(p.relative_to(results)): p.stat().st_mtime_ns for p in (results / "runs").rglob("*") if p.is_file()}


# ------------------------------------------------------------ 2: infra is not the method's failure


def test_infra_failures_are_not_counted_as_method_failures():
    rows = [{"method": "m", "status": "done", "failure": None, "eval_status": "ok", "fps": 30.0}]
    rows += [{"method": "m", "status": "failed", "failure": "infra", "eval_status": None, "fps": None}] * 7
    rows += [{"method": "m", "status": "failed", "failure": "crashed", "eval_status": None, "fps": None}]
    df = pd.DataFrame(rows)
    for c in ("e_t", "e_r", "e_s_sym", "e_align", "e_rmse"):
        df[c] = np.where(df.status == "done", 0.1, np.nan)
    s = method_summary(df).iloc[0]
    assert s["failed"] == 1 and s["infra"] == 7 and s["crashed"] == 1
    assert s["success_pct"] == pytest.approx(50.0)  # 1 done of 2 method results


# ------------------------------------------------------------ 9: non-finite output


def test_non_finite_rows_are_dropped_and_counted_and_all_nan_is_no_output(tmp_path, tiny_dataset):
    methods = [
        fake_method("nan-all", label="nan_all"),
        fake_method("nan-some", label="nan_some"),
        fake_method("inf", label="inf"),
        fake_method("nan-times", label="nan_times"),
    ]
    spec = write_spec(tmp_path, tiny_dataset, methods, datasets=one_sequence(tiny_dataset), directions=["forward"])
    res = campaign(spec)
    df = pd.read_csv(res.results_csv).set_index("method")
    assert df.loc["nan_all", "status"] == "failed" and df.loc["nan_all", "failure"] == "no_output"
    for label, dropped in (("nan_some", 14), ("inf", 10), ("nan_times", 14)):  # 40 frames
        row = df.loc[label]
        assert row.status == "done" and row.eval_status == "ok", label
        assert row.n_poses == 40 - dropped, label
        report = json.loads((Path(row.run_dir) / "run.json").read_text())["trajectory_report"]
        assert report["n_nonfinite_dropped"] == dropped, label
        traj = np.loadtxt(Path(row.run_dir) / "trajectory.txt")
        assert np.isfinite(traj).all() and len(traj) == 40 - dropped
    summary = method_summary(pd.read_csv(res.results_csv)).set_index("method")
    assert summary.loc["nan_all", "success_pct"] == 0.0


def test_the_statistics_use_only_runs_that_ended_done():
    df = pd.DataFrame(
        {
            "method": ["a", "a", "a"],
            "status": ["done", "failed", "failed"],
            "failure": [None, "timeout", "lost"],
            "e_t": [0.1, 0.2, 0.3],
        }
    )
    kept = evaluated(df, ["e_t"])
    assert list(kept.status) == ["done"]


# ------------------------------------------------------------ 6: bad datasets


def bad_copy(tiny_dataset: Path, tmp_path: Path, name: str = "seq_a") -> Path:
    root = tmp_path / "bad"
    shutil.copytree(tiny_dataset / name, root / name)
    return root


def test_binary_camera_txt_is_a_named_dataset_error(tmp_path, tiny_dataset):
    from slamrun.datasets.tum_mono import open_sequence

    root = bad_copy(tiny_dataset, tmp_path)
    (root / "seq_a" / "camera.txt").write_bytes(bytes(range(256)) * 4)
    with pytest.raises(DatasetError) as err:
        open_sequence(root / "seq_a")
    assert "camera.txt" in str(err.value) and "text" in str(err.value)


def test_non_finite_calibration_is_refused(tmp_path, tiny_dataset):
    from slamrun.datasets.tum_mono import open_sequence

    root = bad_copy(tiny_dataset, tmp_path)
    cam = root / "seq_a" / "camera.txt"
    lines = cam.read_text().splitlines()
    lines[0] = "nan " + " ".join(lines[0].split()[1:])
    cam.write_text("\n".join(lines) + "\n")
    with pytest.raises(DatasetError, match=r"camera.txt:1: .*finite"):
        open_sequence(root / "seq_a")


def test_validate_opens_the_sequences_as_the_campaign_does(tmp_path, tiny_dataset):
    from slamrun.cli import main

    root = tmp_path / "data"
    for name in ("seq_a", "seq_b"):
        shutil.copytree(tiny_dataset / name, root / name)
    zpath = root / "seq_a" / "images.zip"
    zpath.write_bytes(zpath.read_bytes()[: zpath.stat().st_size // 2])  # truncated download
    times = root / "seq_b" / "times.txt"
    times.write_text("".join(times.read_text().splitlines(keepends=True)[:-3]))  # short times.txt
    spec = write_spec(tmp_path, root, [fake_method()])
    assert main(["validate", str(spec)]) == 1


def test_a_sequence_without_ground_truth_is_announced_before_any_run(tmp_path, tiny_dataset):
    root = bad_copy(tiny_dataset, tmp_path)
    (root / "seq_a" / "groundtruthSync.txt").unlink()
    spec = write_spec(tmp_path, root, [fake_method()], datasets=one_sequence(root), directions=["forward"])
    said = []

    def log(msg):
        said.append(msg)

    started = []
    res = campaign(spec, log=log, on_event=lambda kind, *a: started.append(len(said)) if kind == "started" else None)
    warnings = [i for i, m in enumerate(said) if "groundtruthSync.txt" in m and "cannot be evaluated" in m]
    assert warnings and warnings[0] < started[0]
    assert res.counts["done"] == 1


# ------------------------------------------------------------ 5: different data, same sequence name


def test_new_data_under_the_same_sequence_name_makes_new_runs(tmp_path, tiny_dataset):
    spec = write_spec(tmp_path, tiny_dataset, [fake_method()], datasets=one_sequence(tiny_dataset))
    first = campaign(spec)
    assert first.counts["done"] == 2
    other = tmp_path / "other"
    generate(other / "seq_a", frames=40, seed=77, size=(160, 120))  # other images, same name
    spec2 = write_spec(
        tmp_path, other, [fake_method()], datasets=[{"name": "synth2", "path": str(other), "sequences": ["seq_a"]}]
    )
    second = campaign(spec2)
    assert second.added == 2 and second.counts["done"] == 2
    df = pd.read_csv(second.results_csv)
    assert set(df.dataset) == {"synth2"} and len(df) == 2
    assert {r["dataset"] for r in ledger_rows(second.results) if not r["active"]} == {"s"}  # old rows kept as they were


# ------------------------------------------------------------ 4: a lost ledger


@pytest.mark.parametrize("damage", ["delete", "truncate"])
def test_a_lost_ledger_imports_finished_runs_instead_of_redoing_them(tmp_path, tiny_dataset, damage):
    marker = tmp_path / "starts.txt"
    spec = write_spec(tmp_path, tiny_dataset, [fake_method(extra=["--marker", str(marker)])], trials=2)
    first = campaign(spec)
    assert first.counts["done"] == 8
    before = folder_state(first.results)
    ledger = first.results / "ledger.sqlite"
    if damage == "delete":
        for p in first.results.glob("ledger.sqlite*"):
            p.unlink()
    else:
        ledger.write_bytes(b"")
    n_starts = len(marker.read_text().splitlines())
    second = campaign(spec)
    assert second.counts["done"] == 8
    assert len(marker.read_text().splitlines()) == n_starts  # nothing ran again
    assert folder_state(second.results) == before  # nothing rewritten
    df = pd.read_csv(second.results_csv)
    assert df.e_align.notna().all() and df.wall_s.notna().all()


def test_a_ledger_that_vanishes_mid_campaign_stops_it(tmp_path, tiny_dataset):
    spec = write_spec(tmp_path, tiny_dataset, [fake_method(sleep=0.3)], trials=3, lanes=1)
    results = tmp_path / "results"

    def on_event(kind, run, lane, info):
        if kind == "finished" and (results / "ledger.sqlite").exists():
            for p in results.glob("ledger.sqlite*"):
                p.unlink()

    with pytest.raises(SlamRunError) as err:
        campaign(spec, on_event=on_event)
    msg = str(err.value)
    assert "ledger.sqlite" in msg and "vanished" in msg and "run the same command again" in msg
    finished = folder_state(results)
    assert 0 < len({Path(k).parent for k in finished if k.endswith("run.json")}) < 12
    resumed = campaign(spec)
    assert resumed.counts["done"] == 12
    assert all(folder_state(results)[k] == v for k, v in finished.items())


# ------------------------------------------------------------ 3 and 7: the view cache


def test_a_deleted_view_cache_is_rebuilt_not_charged(tmp_path, tiny_dataset):
    spec = write_spec(tmp_path, tiny_dataset, [fake_method(sleep=0.2)], trials=2, lanes=1)
    cache = tmp_path / "cache"
    deleted = []

    def on_event(kind, run, lane, info):
        if kind == "finished" and not deleted:
            shutil.rmtree(cache)
            deleted.append(run.key.id)

    res = campaign(spec, on_event=on_event)
    df = pd.read_csv(res.results_csv)
    charged = df[df.status != "done"][["sequence", "direction", "trial", "failure", "message"]].to_dict("records")
    assert deleted and res.counts == {"pending": 0, "running": 0, "done": 8, "failed": 0}, charged


def test_an_observer_that_raises_never_changes_a_runs_record(tmp_path, tiny_dataset, capsys):
    """The event hook (the live display, a user's callback) raising on a finished run must not record the run again
    as an infrastructure failure: the deleted-cache test above failed so when its rmtree met a view being written
    (the run it had just recorded done became `infra`). The error is printed, the record stands."""
    spec = write_spec(tmp_path, tiny_dataset, [fake_method()], datasets=one_sequence(tiny_dataset), trials=2, lanes=1)

    def on_event(kind, run, lane, info):
        if kind == "finished":
            raise OSError(39, "Directory not empty", "cache")

    res = campaign(spec, on_event=on_event)
    assert res.counts == {"pending": 0, "running": 0, "done": 4, "failed": 0}
    assert "an event observer failed" in capsys.readouterr().err


def test_a_method_that_damages_the_view_does_not_charge_later_runs(tmp_path, tiny_dataset):
    methods = [{**fake_method("damage-view", label="vandal"), "trials": 1}, fake_method(label="honest")]
    spec = write_spec(
        tmp_path, tiny_dataset, methods, datasets=one_sequence(tiny_dataset), directions=["forward"], trials=3, lanes=1
    )
    res = campaign(spec)
    df = pd.read_csv(res.results_csv)
    honest = df[df.method == "honest"]
    assert len(honest) == 3 and (honest.status == "done").all() and (honest.eval_status == "ok").all()
    # the view in the cache is whole again: no stray file, times.txt as prepared
    views = [p for p in (tmp_path / "cache").iterdir() if p.is_dir() and not p.name.startswith(".")]
    for view in views:
        assert not (view / "stray-file.txt").exists()
        assert len((view / "times.txt").read_text().splitlines()) == 40


# ------------------------------------------------------------ 8: descendants in their own session


@pytest.mark.parametrize("mode", ["setsid-child", "setsid-quiet-child"])
def test_a_child_in_its_own_session_ends_with_its_run(tmp_path, tiny_dataset, mode):
    marker = tmp_path / "pids.txt"
    spec = write_spec(
        tmp_path,
        tiny_dataset,
        [fake_method(mode, extra=["--marker", str(marker), "--child-sleep", "60"])],
        datasets=one_sequence(tiny_dataset),
        directions=["forward"],
        timeout_s=15,
    )
    t0 = time.monotonic()
    res = campaign(spec)
    took = time.monotonic() - t0
    assert res.counts["done"] == 1
    assert took < 15 + 10, f"the lane was held {took:.0f} s"
    child = int(next(line.split()[1] for line in marker.read_text().splitlines() if line.startswith("child")))
    assert not _alive(child), "the run's setsid child outlived it"


def test_a_hanging_method_with_a_setsid_child_frees_the_lane_at_the_timeout(tmp_path, tiny_dataset):
    marker = tmp_path / "pids.txt"
    spec = write_spec(
        tmp_path,
        tiny_dataset,
        [fake_method("setsid-child", sleep=120, extra=["--marker", str(marker), "--child-sleep", "120"])],
        datasets=one_sequence(tiny_dataset),
        directions=["forward"],
        timeout_s=4,
    )
    t0 = time.monotonic()
    res = campaign(spec)
    assert time.monotonic() - t0 < 4 + 10
    assert ledger_rows(res.results)[0]["failure"] == "timeout"
    child = int(next(line.split()[1] for line in marker.read_text().splitlines() if line.startswith("child")))
    assert not _alive(child)


def _alive(pid: int) -> bool:
    try:
        return psutil.Process(pid).status() != psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return False


# ------------------------------------------------------------ the import circle


def test_campaign_and_backends_import_in_one_direction():
    import ast

    root = Path(__file__).resolve().parents[1] / "runner" / "backends"
    for path in root.glob("*.py"):
        tree = ast.parse(path.read_text())
        imported = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module}
        assert "slamrun.engine.campaign" not in imported, f"{path.name} imports slamrun.campaign"


# ------------------------------------------------------------ a method's environment reaches its process


def test_a_methods_environment_reaches_its_process(tmp_path, tiny_dataset):
    """Method.environment() (ORB-SLAM2's loop-closure switch, DF-ORB-SLAM's pose switch, the CPU settings of the
    CNN methods) is set in the process a run starts; `external` takes it from its `env` parameter."""
    fake = fake_method()
    fake["params"]["argv"] = ["sh", "-c", 'printf %s "$SLAMRUN_TEST_VALUE" > env.txt; exec "$@"', "sh"] + fake[
        "params"
    ]["argv"]
    fake["params"]["env"] = {"SLAMRUN_TEST_VALUE": "loop-off"}
    spec = write_spec(tmp_path, tiny_dataset, [fake], datasets=one_sequence(tiny_dataset), directions=["forward"])
    res = campaign(spec)
    assert res.counts["done"] == 1
    (seen,) = list((res.results / "runs").rglob("raw/env.txt"))
    assert seen.read_text() == "loop-off"


def test_a_run_clears_its_own_half_written_attempts_and_leaves_its_siblings(tmp_path, tiny_dataset):
    """Before attempt n, attempts 1..n of the same run are removed (one check each, not a listing of a folder of
    thousands of runs); another run's attempt and a later-numbered leftover stay; recovery (no number) clears
    every attempt of the run it finds."""
    from slamrun.engine.paths import RunPaths
    from slamrun.engine.plan import plan

    spec = write_spec(
        tmp_path, tiny_dataset, [fake_method()], datasets=one_sequence(tiny_dataset), directions=["forward"], trials=2
    )
    runs = plan(load_spec(spec))
    mine, other = (RunPaths(tmp_path / "res", r.key) for r in runs[:2])
    assert mine.final.parent == other.final.parent  # two trials: siblings
    for paths, attempts in ((mine, (1, 2, 5)), (other, (1,))):
        for a in attempts:
            (paths.staging(a) / "raw").mkdir(parents=True)
            (paths.staging(a) / "raw" / "x.txt").write_text("half")
    mine.clear_staging(up_to=2)
    assert not mine.staging(1).exists() and not mine.staging(2).exists()
    assert mine.staging(5).exists() and other.staging(1).exists()
    mine.clear_staging()
    assert not mine.staging(5).exists() and other.staging(1).exists()
