"""`slamrun evaluate` as a user runs it (real subprocesses, real files): a campaign's runs re-evaluated from their
sequence folder give results.csv's figures on every layout; a raw ground-truth file in another frame says so; the
exit code says whether every file was evaluated; hostile files and options end in one clear line, in bounded time
and memory."""

from __future__ import annotations

import json
import math
import os
import resource
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from slamrun.datasets.make_synthetic import generate
from tests.test_dataset_layouts import EUROC_SENSOR

ROOT = Path(__file__).resolve().parents[1]
LAYOUT_SEQUENCES = {
    "tum-mono": "sequence_synth",
    "euroc": "V1_synth",
    "kitti": "00",
    "tum-rgbd": "rgbd_dataset_freiburg1_synth",
    "tum-vi": "room_synth",
}
# every figure a campaign writes into results.csv, whatever the metric (named here, not taken from the code)
FIGURES = (
    *("e_t", "e_r", "e_s", "e_s_sym", "e_align", "e_start", "e_end", "e_rmse"),
    *("ate_rmse", "ate_mean", "ate_median", "ate_max", "rpe_t_rmse", "rpe_r_rmse", "rpe_pairs"),
    *("kitti_t_pct", "kitti_r_deg_m"),
)


def slamrun(*args, limit_as: int | None = None, timeout: float = 120) -> subprocess.CompletedProcess:
    """`slamrun ARGS` as a separate process (optionally under an address-space limit)."""

    def limited() -> None:
        if limit_as:
            resource.setrlimit(resource.RLIMIT_AS, (limit_as, resource.RLIM_INFINITY))

    return subprocess.run(
        [sys.executable, "-m", "slamrun.cli", *map(str, args)],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=ROOT,
        preexec_fn=limited,
    )


def json_rows(out: subprocess.CompletedProcess) -> list[dict]:
    return [json.loads(line) for line in out.stdout.splitlines()]


def sequence_folder(root: Path, layout: str) -> Path:
    parent = root / layout / ("sequences" if layout == "kitti" else "")
    return parent / LAYOUT_SEQUENCES[layout]


@pytest.fixture(scope="module")
def campaign(tmp_path_factory) -> tuple[Path, pd.DataFrame]:
    """A small real campaign: reference_vo, forward and backward, one trial, on one synthetic sequence of each
    layout (each dataset with its layout's default metrics). Returns the data folder and results.csv."""
    from slamrun.engine.campaign import run_campaign
    from slamrun.engine.spec_file import load_spec
    from tests.conftest import write_spec

    root = tmp_path_factory.mktemp("evaluate_campaign")
    datasets = []
    for layout in LAYOUT_SEQUENCES:
        folder = generate(sequence_folder(root / "data", layout), frames=60, seed=3, size=(320, 240), layout=layout)
        datasets.append({"name": layout, "path": str(folder.parent), "sequences": [folder.name], "layout": layout})
    spec = write_spec(root, root, [{"name": "reference_vo"}], datasets=datasets, timeout_s=120)
    res = run_campaign(load_spec(spec), log=lambda *a: None)
    return root / "data", pd.read_csv(res.results_csv)


@pytest.mark.parametrize("layout", sorted(LAYOUT_SEQUENCES))
def test_a_campaigns_runs_reevaluated_from_their_sequence_folder_equal_results_csv(campaign, layout):
    data, df = campaign
    rows = df[df.dataset == layout].sort_values("direction")
    assert list(rows.direction) == ["backward", "forward"] and rows.status.eq("done").all(), rows.message.tolist()
    files = [Path(d) / "trajectory.txt" for d in rows.run_dir]
    out = slamrun("evaluate", "--gt", sequence_folder(data, layout), "--json", *files)
    assert out.returncode == 0, out.stderr
    assert "Traceback" not in out.stderr
    got = json_rows(out)
    assert [g["file"] for g in got] == [str(f) for f in files]
    for (_, row), res in zip(rows.iterrows(), got, strict=True):
        assert res["status"] == row.eval_status == "ok" and res["n_poses"] == row.n_poses
        compared = 0
        for name in FIGURES:
            if name in df.columns and not pd.isna(row[name]):
                assert res[name] == pytest.approx(row[name], rel=1e-9, abs=1e-12), (layout, row.direction, name)
                compared += 1
            else:  # a figure the run does not have is not made up either
                assert res.get(name) is None, (layout, row.direction, name)
        if layout != "tum-mono" and pd.isna(row.rpe_t_rmse):  # a track shorter than RPE's 1 s: said, not made up
            assert "no pose pair 1 s apart" in res["detail"]
            compared += 3
        assert compared >= 7  # TUM-Mono's, or ATE's and RPE's with its pairs
    if layout == "kitti":  # its default metrics include KITTI's segments: missing on a short path, and said
        assert all("kitti_t_pct" in r and "no segment" in r["detail"] for r in got)


def test_a_run_of_another_sequence_is_refused_unless_asked(campaign):
    """run.json beside a trajectory names its sequence: against another sequence's folder it is refused with both
    named (once evaluated without a word); --any-sequence evaluates it anyway."""
    data, df = campaign
    run = df[(df.dataset == "euroc") & (df.direction == "forward")].iloc[0]
    other = sequence_folder(data, "tum-vi")
    traj = Path(run.run_dir) / "trajectory.txt"
    out = slamrun("evaluate", "--gt", other, traj)
    assert out.returncode == 1 and "Traceback" not in out.stderr
    assert f"of sequence {LAYOUT_SEQUENCES['euroc']!r}, not of {other}" in out.stderr and "--any-sequence" in out.stderr
    forced = slamrun("evaluate", "--gt", other, "--any-sequence", "--json", traj)
    assert "of sequence" not in forced.stderr and len(json_rows(forced)) == 1
    same = slamrun("evaluate", "--gt", sequence_folder(data, "euroc"), traj)
    assert same.returncode == 0, same.stderr


def test_kitti_file_form_and_folder_form_give_one_status(campaign):
    """The synthetic drive is shorter than KITTI's 100 m segments: the folder form notes it and says ok; the poses
    file with its times (the same data) once said failed, exit 1."""
    data, df = campaign
    run = df[(df.dataset == "kitti") & (df.direction == "forward")].iloc[0]
    folder = sequence_folder(data, "kitti")
    traj = Path(run.run_dir) / "trajectory.txt"
    by_folder = slamrun("evaluate", "--gt", folder, "--json", traj)
    poses = folder.parent.parent / "poses" / f"{folder.name}.txt"
    by_file = slamrun("evaluate", "--gt", poses, "--times", folder / "times.txt", "--json", traj)
    assert by_folder.returncode == by_file.returncode == 0, (by_folder.stderr, by_file.stderr)
    (a,), (b,) = json_rows(by_folder), json_rows(by_file)
    assert a["status"] == b["status"] == "ok" and "no segment" in a["detail"] and "no segment" in b["detail"]


def test_euroc_raw_state_csv_says_its_frame_and_names_the_folder(campaign):
    """The body-frame csv as it is: evaluated (its own figures), with a note naming the camera frame's folder."""
    data, df = campaign
    folder = sequence_folder(data, "euroc")
    run = df[(df.dataset == "euroc") & (df.direction == "forward")].iloc[0]
    csv = folder / "mav0" / "state_groundtruth_estimate0" / "data.csv"
    out = slamrun("evaluate", "--gt", csv, "--metric", "ate", "--json", Path(run.run_dir) / "trajectory.txt")
    assert out.returncode == 0, out.stderr
    assert "body (IMU) frame" in out.stderr and f"--gt {folder}" in out.stderr
    (raw,) = json_rows(out)
    assert raw["status"] == "ok" and not math.isclose(raw["ate_rmse"], run.ate_rmse, rel_tol=1e-3)
    # the folder form says nothing of the kind
    folder_out = slamrun("evaluate", "--gt", folder, "--metric", "ate", Path(run.run_dir) / "trajectory.txt")
    assert folder_out.returncode == 0 and "body" not in folder_out.stderr


# ---------------------------------------------------------------- real ground truth: evo's test data


T_BS = np.array(
    [
        [0.0148655429818, -0.999880929698, 0.00414029679422, -0.0216401454975],
        [0.999557249008, 0.0149672133247, 0.025715529948, -0.064676986768],
        [-0.0257744366974, 0.00375618835797, 0.999660727178, 0.00981073058949],
        [0.0, 0.0, 0.0, 1.0],
    ]
)


def image_files(folder: Path, names: list[str], size: tuple[int, int]) -> None:
    """One real PNG of the camera's size, hard-linked under every frame name."""
    import cv2

    folder.mkdir(parents=True, exist_ok=True)
    first = folder / names[0]
    cv2.imwrite(str(first), np.full((size[1], size[0]), 128, np.uint8))
    for name in names[1:]:
        os.link(first, folder / name)


@pytest.fixture
def v1_02(shared_data, tmp_path) -> tuple[Path, Path]:
    """EuRoC V1_02 as a sequence folder (its real state ground truth and camera extrinsics, frames at ground-truth
    samples) and the real estimate V102.txt moved to those frame times. Returns (folder, estimate)."""
    from slamrun.core.trajectory import read_euroc_csv, read_tum

    evo_data = shared_data / "evo_test_data"
    body = read_euroc_csv(evo_data / "V102_groundtruth.csv")
    est = read_tum(evo_data / "V102.txt")
    stamps_ns = [int(line.split(",")[0]) for line in (evo_data / "V102_groundtruth.csv").read_text().splitlines()[1:]]
    nearest = np.abs(body.timestamps[None, :] - est.timestamps[:, None]).argmin(axis=1)
    keep = np.flatnonzero(np.diff(nearest, prepend=-1) > 0)  # one frame per ground-truth sample
    ns = [stamps_ns[i] for i in nearest[keep]]
    root = tmp_path / "V1_02_medium"
    cam = root / "mav0" / "cam0"
    image_files(cam / "data", [f"{v}.png" for v in ns], (752, 480))
    (cam / "data.csv").write_text("#timestamp [ns],filename\n" + "".join(f"{v},{v}.png\n" for v in ns))
    (cam / "sensor.yaml").write_text(EUROC_SENSOR)
    (root / "mav0" / "state_groundtruth_estimate0").mkdir(parents=True)
    shutil.copyfile(evo_data / "V102_groundtruth.csv", root / "mav0" / "state_groundtruth_estimate0" / "data.csv")
    frame_t = body.timestamps[nearest[keep]]
    rows = np.column_stack([frame_t, est.positions[keep], est.quaternions[keep]])
    np.savetxt(tmp_path / "V102_at_frames.txt", rows, fmt="%.17g")
    return root, tmp_path / "V102_at_frames.txt"


def test_euroc_v1_02_folder_form_equals_evo_on_the_camera_frame(v1_02, shared_data):
    """V1_02's real ground truth through the folder: ATE and RPE equal evo's on the body poses carried to the camera
    with V1's T_BS (evo's own transform, association and Sim(3) alignment); the raw csv gives other figures and
    says so."""
    pytest.importorskip("evo", reason="evo (a development dependency) is the reference")
    from evo.core import metrics, sync
    from evo.tools import file_interface

    folder, est_file = v1_02
    out = slamrun("evaluate", "--gt", folder, "--json", "--delta-unit", "evo-f", est_file)
    assert out.returncode == 0, out.stderr
    (ours,) = json_rows(out)
    ref = file_interface.read_euroc_csv_trajectory(str(folder / "mav0/state_groundtruth_estimate0/data.csv"))
    ref.transform(T_BS, right_mul=True)  # body poses to camera poses
    est = file_interface.read_tum_trajectory_file(str(est_file))
    ref, est = sync.associate_trajectories(ref, est, max_diff=0.001)
    est.align(ref, correct_scale=True)
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((ref, est))
    rpe = metrics.RPE(metrics.PoseRelation.translation_part, delta=1, delta_unit=metrics.Unit.frames)
    rpe.process_data((ref, est))
    assert ours["status"] == "ok" and ours["n_poses"] == est.num_poses
    assert ours["ate_rmse"] == pytest.approx(ape.get_statistic(metrics.StatisticsType.rmse), rel=1e-6)
    assert ours["ate_max"] == pytest.approx(ape.get_statistic(metrics.StatisticsType.max), rel=1e-6)
    assert ours["rpe_t_rmse"] == pytest.approx(rpe.get_statistic(metrics.StatisticsType.rmse), rel=1e-6)
    raw = slamrun("evaluate", "--gt", shared_data / "evo_test_data" / "V102_groundtruth.csv", "--json", est_file)
    assert raw.returncode == 0 and "body (IMU) frame" in raw.stderr and "--gt SEQUENCE_FOLDER" in raw.stderr
    assert not math.isclose(json_rows(raw)[0]["ate_rmse"], ours["ate_rmse"], rel_tol=1e-3)


def test_tum_mono_metric_on_a_euroc_csv_is_a_clear_error(shared_data):
    """The issue's reproduction: once a numpy traceback ("could not convert string ...")."""
    csv = shared_data / "evo_test_data" / "V102_groundtruth.csv"
    out = slamrun("evaluate", "--gt", csv, "--metric", "tum-mono", shared_data / "evo_test_data" / "V102.txt")
    assert out.returncode == 1 and "Traceback" not in out.stderr
    assert str(csv) in out.stderr and "EuRoC" in out.stderr and "groundtruthSync" in out.stderr


def test_kitti_00_folder_form_gives_its_three_default_metrics(shared_data, tmp_path):
    """KITTI 00 as a sequence folder (its poses beside it, its times), ORB-SLAM2's KITTI-format estimate: ATE with
    SE(3) equals evo's saved result, and the KITTI segments metric (3.7 km) is there too."""
    evo_data = shared_data / "evo_test_data"
    root = tmp_path / "dataset" / "sequences" / "00"
    n = len((evo_data / "KITTI_00_gt_times.txt").read_text().split())
    image_files(root / "image_0", [f"{i:06d}.png" for i in range(n)], (1241, 376))
    shutil.copyfile(evo_data / "KITTI_00_gt_times.txt", root / "times.txt")
    p0 = "7.188560000000e+02 0 6.071928000000e+02 0 0 7.188560000000e+02 1.852157000000e+02 0 0 0 1 0"
    (root / "calib.txt").write_text(f"P0: {p0}\nP1: {p0}\n")
    (tmp_path / "dataset" / "poses").mkdir()
    shutil.copyfile(evo_data / "KITTI_00_gt.txt", tmp_path / "dataset" / "poses" / "00.txt")
    orb = evo_data / "KITTI_00_ORB.txt"
    out = slamrun("evaluate", "--gt", root, "--est-format", "kitti", "--align", "se3", "--json", orb)
    assert out.returncode == 0, out.stderr
    (res,) = json_rows(out)
    assert res["status"] == "ok" and res["n_poses"] == n
    # evo's saved result (res_files/orb_ape.zip: "APE w.r.t. translation part (m) (with SE(3) Umeyama alignment)")
    assert res["ate_rmse"] == pytest.approx(1.3034497145650266, rel=1e-6)
    assert res["rpe_t_rmse"] > 0 and res["kitti_t_pct"] > 0
    plain = slamrun(
        "evaluate", "--gt", root, "--est-format", "kitti", "--align", "none", "--metric", "kitti", "--json", orb
    )
    assert plain.returncode == 0, plain.stderr
    assert json_rows(plain)[0]["kitti_t_pct"] == pytest.approx(0.70, abs=0.005)  # KITTI's published 0.70 %


# ---------------------------------------------------------------- exit codes


def tum_file(path: Path, t: np.ndarray, pos: np.ndarray) -> Path:
    np.savetxt(path, np.column_stack([t, pos, np.tile([0, 0, 0, 1.0], (len(t), 1))]), fmt="%.17g")
    return path


@pytest.fixture
def loop(tmp_path) -> tuple[Path, Path]:
    """A 60-pose ground truth (TUM) and an estimate of it at half scale."""
    t = 1000.0 + np.arange(60) / 20.0
    phase = np.linspace(0, 2 * np.pi, 60)
    pos = np.column_stack([np.cos(phase), np.sin(phase), 0.1 * phase])
    return tum_file(tmp_path / "gt.txt", t, pos), tum_file(tmp_path / "est.txt", t, 0.5 * pos + 1)


def test_exit_code_says_whether_every_file_was_evaluated(loop, tmp_path):
    gt, est = loop
    ok = slamrun("evaluate", "--gt", gt, "--metric", "ate", est, est)
    assert ok.returncode == 0 and ok.stderr == "" and ok.stdout.count(": ok") == 2
    (tmp_path / "bad.txt").write_text("1 2 3\n")
    far = tum_file(tmp_path / "far.txt", np.arange(60) * 0.05, np.zeros((60, 3)))  # no timestamp in common
    out = slamrun("evaluate", "--gt", gt, "--metric", "ate", "--json", est, tmp_path / "bad.txt", far)
    assert out.returncode == 1 and "2 of 3 file(s) could not be evaluated" in out.stderr
    assert [r["status"] for r in json_rows(out)] == ["ok", "unreadable", "failed"]
    short = slamrun("evaluate", "--gt", gt, "--metric", "kitti", est)  # a 6 m path: no 100 m segment
    assert short.returncode == 1 and "failed" in short.stdout and "no segment" in short.stdout
    assert "1 of 1 file(s)" in short.stderr


# ---------------------------------------------------------------- hostile inputs and options


def test_dev_zero_and_fifos_are_refused_at_once_in_bounded_memory(loop, tmp_path):
    """/dev/zero as a trajectory or as --times was read until 6 GB; a FIFO blocked for ever. Under a 2 GiB address
    space limit, each is refused unread with its name."""
    gt, est = loop
    fifo = tmp_path / "fifo.txt"
    os.mkfifo(fifo)
    sparse = tmp_path / "huge.txt"
    with open(sparse, "wb") as f:
        f.truncate(300 * 2**20)  # beyond any trajectory; no disk used
    limit = 2 * 2**30
    out = slamrun("evaluate", "--gt", gt, "--metric", "ate", "--json", "/dev/zero", fifo, sparse, est, limit_as=limit)
    assert out.returncode == 1 and "Traceback" not in out.stderr, out.stderr
    rows = json_rows(out)
    assert [r["status"] for r in rows] == ["unreadable", "unreadable", "unreadable", "ok"]
    assert "/dev/zero: a character device" in rows[0]["detail"] and "FIFO" in rows[1]["detail"]
    assert "bytes; a trajectory file is at most" in rows[2]["detail"]
    kitti_gt = tmp_path / "poses.txt"
    np.savetxt(kitti_gt, np.tile(np.eye(4)[:3].ravel(), (60, 1)))
    for times in ("/dev/zero", fifo, sparse):
        bad = slamrun("evaluate", "--gt", kitti_gt, "--metric", "ate", "--times", times, est, limit_as=limit)
        assert bad.returncode == 1 and f"{times}:" in bad.stderr and "Traceback" not in bad.stderr, bad.stderr
    for ground_truth in ("/dev/zero", fifo):
        bad = slamrun("evaluate", "--gt", ground_truth, est, limit_as=limit)
        assert bad.returncode == 1 and f"{ground_truth}:" in bad.stderr and "Traceback" not in bad.stderr


@pytest.mark.parametrize(
    "option",
    [
        ["--jobs", "0"],
        ["--jobs", "-2"],
        ["--tolerance", "nan"],
        ["--tolerance", "inf"],
        ["--tolerance", "-0.1"],
        ["--delta", "nan"],
        ["--delta", "0"],
    ],
)
def test_a_meaningless_option_is_a_clear_error(loop, option):
    gt, est = loop
    out = slamrun("evaluate", "--gt", gt, "--metric", "rpe", *option, est)
    assert out.returncode == 2 and f"argument {option[0]}: '{option[1]}'" in out.stderr, out.stderr
    assert "Traceback" not in out.stderr and out.stdout == ""


def test_an_alignment_over_more_poses_than_there_are_fails_that_file(loop):
    gt, est = loop
    out = slamrun("evaluate", "--gt", gt, "--metric", "ate", "--align", "first:100000", "--json", est)
    assert out.returncode == 1, out.stderr
    (row,) = json_rows(out)
    assert row["status"] == "failed" and "first 100000 poses" in row["detail"] and "60" in row["detail"]
    assert "ate_rmse" not in row
    fits = slamrun("evaluate", "--gt", gt, "--metric", "ate", "--align", "first:60", est)
    assert fits.returncode == 0, fits.stderr


def test_every_wrong_format_or_combination_is_one_line_naming_the_file(campaign, loop, tmp_path):
    data, _ = campaign
    gt, est = loop
    euroc = sequence_folder(data, "euroc")
    garbage = tmp_path / "garbage.bin"
    garbage.write_bytes(bytes(range(256)) * 4)
    empty = tmp_path / "empty.txt"
    empty.write_text("# timestamp tx ty tz qx qy qz qw\n")
    cases = [
        (["--gt", gt, "--gt-format", "kitti"], f"{gt}: KITTI poses carry no timestamps"),
        (["--gt", gt, "--gt-format", "euroc"], f"{gt}:1:"),
        (["--gt", gt, "--gt-format", "tum", "--metric", "tum-mono"], "groundtruthSync"),
        (["--gt", garbage], f"{garbage}"),
        (["--gt", empty, "--metric", "ate"], f"{empty}: no finite pose"),
        (["--gt", empty], f"{empty}: no finite pose; expected a TUM trajectory"),  # no NaN row: a plain TUM file
        (["--gt", empty, "--gt-format", "tum-mono"], f"{empty}: no pose row"),
        (["--gt", gt, "--est-format", "kitti"], "give the sequence's times.txt with --times"),
        (["--gt", euroc, "--tolerance", "0.1"], f"{euroc}: a sequence folder is evaluated as a campaign does"),
        (["--gt", gt, "--delta-unit", "frames"], "--delta-unit frames counts the sequence's frames"),
        (["--gt", euroc, "--times", gt], "--times"),
        (["--gt", tmp_path], f"{tmp_path}: no sequence of a layout slamrun reads"),
        (["--gt", tmp_path / "missing.txt"], "missing.txt: the ground truth"),
    ]
    for args, said in cases:
        out = slamrun("evaluate", *args, est)
        assert out.returncode == 1 and said in out.stderr, (args, out.stderr)
        assert "Traceback" not in out.stderr and len(out.stderr.strip().splitlines()) == 1, out.stderr


# ---------------------------------------------------------------- a ground-truth file's default metrics


EVO_DEFAULTS = [  # (ground truth, estimate) of evo's test data: plain TUM files and an EuRoC state csv
    ("freiburg1_xyz-groundtruth.txt", "freiburg1_xyz-rgbdslam.txt"),
    ("fr2_desk_groundtruth.txt", "fr2_desk_ORB_kf_mono.txt"),
    ("V102_groundtruth.csv", "V102.txt"),
]


@pytest.mark.parametrize(("gt_name", "est_name"), EVO_DEFAULTS)
def test_a_plain_tum_or_euroc_ground_truth_file_gives_ate_and_rpe_by_default(shared_data, gt_name, est_name):
    """The issue: fr1/xyz's groundtruth.txt once got TUM-Mono's metric by default ("unassociated": no ground truth
    within 1 ms), where an evo user expects ATE and RPE. Now a file that is not TUM-Mono's gets ATE and RPE at 1 s,
    the very figures `--metric ate --metric rpe` gives."""
    gt, est = shared_data / "evo_test_data" / gt_name, shared_data / "evo_test_data" / est_name
    default = slamrun("evaluate", "--gt", gt, "--json", est)
    asked = slamrun("evaluate", "--gt", gt, "--metric", "ate", "--metric", "rpe", "--json", est)
    assert default.returncode == asked.returncode == 0, (default.stdout, default.stderr)
    (row,) = json_rows(default)
    assert row == json_rows(asked)[0] and default.stderr == asked.stderr
    assert row["status"] == "ok" and row["ate_rmse"] > 0 and row["rpe_t_rmse"] > 0 and row["rpe_pairs"] > 0
    assert (row["delta"], row["delta_unit"]) == (1.0, "s") and "e_t" not in row


def test_an_explicit_tum_mono_metric_on_a_plain_tum_file_keeps_its_behaviour(shared_data, loop):
    """--metric tum-mono reads a TUM file as a groundtruthSync (its halves the segments), as before: fr1/xyz's
    estimate at the camera's frames has no ground truth within 1 ms; an estimate at the file's own times has
    TUM-Mono's figures, the benchmark's evaluator's on that file."""
    from slamrun.core.evaluation import tum_mono
    from slamrun.core.trajectory import read_tum
    from slamrun.datasets.groundtruth import read_groundtruth_sync

    data = shared_data / "evo_test_data"
    fr1 = slamrun(
        "evaluate", "--gt", data / "freiburg1_xyz-groundtruth.txt", "--metric", "tum-mono", "--json",
        data / "freiburg1_xyz-rgbdslam.txt",
    )  # fmt: skip
    assert fr1.returncode == 1 and "1 of 1 file(s) could not be evaluated" in fr1.stderr
    (row,) = json_rows(fr1)
    assert row["status"] == "unassociated" and row["n_poses"] == 788
    assert row["detail"] == "633 poses (first t=1305031102.160407) have no GT within 1 ms"
    gt, est = loop
    out = slamrun("evaluate", "--gt", gt, "--metric", "tum-mono", "--json", est)
    assert out.returncode == 0, out.stderr
    (row,) = json_rows(out)
    ref = tum_mono(read_groundtruth_sync(gt), read_tum(est))
    assert row["status"] == "ok" and "ate_rmse" not in row
    for name in ("e_t", "e_r", "e_s", "e_align", "e_start", "e_end", "e_rmse"):
        assert row[name] == pytest.approx(getattr(ref, name), rel=1e-12, abs=1e-15), name
    default = slamrun("evaluate", "--gt", gt, "--json", est)  # the same file without --metric: ATE and RPE
    assert default.returncode == 0 and "ate_rmse" in json_rows(default)[0] and "e_t" not in json_rows(default)[0]


@pytest.fixture(scope="module")
def tum_mono_sequence(tmp_path_factory) -> tuple[Path, Path]:
    """A TUM-Mono sequence written by `slamrun synth` (groundtruthSync.txt: poses at the start and the end, NaN rows
    between) and an estimate: its full path at the frames, at another scale and place, drifting. Returns the
    groundtruthSync.txt and the estimate."""
    from slamrun.core.trajectory import read_tum

    root = tmp_path_factory.mktemp("tum_mono")
    folder = generate(root / "sequence_01", frames=60, seed=4, size=(160, 120), layout="tum-mono")
    full = read_tum(folder / "groundtruth_full.txt")
    drift = np.linspace(0, 0.05, len(full))[:, None] * [1.0, -0.5, 0.2]
    est = tum_file(root / "est.txt", full.timestamps, 0.4 * full.positions + [1.0, 2.0, 3.0] + drift)
    return folder / "groundtruthSync.txt", est


def test_tum_monos_groundtruthsync_keeps_tum_monos_metric_by_default_also_renamed(tum_mono_sequence, tmp_path):
    """groundtruthSync.txt gives TUM-Mono's figures by default (by its name), and so does a copy under another name
    (by its content: poses at the start and the end, NaN rows between), with a note saying why; explicit metrics
    still win."""
    sync, est = tum_mono_sequence
    renamed = tmp_path / "sequence_01_gt.txt"
    shutil.copyfile(sync, renamed)
    asked = slamrun("evaluate", "--gt", sync, "--metric", "tum-mono", "--json", est)
    assert asked.returncode == 0, asked.stderr
    (ref,) = json_rows(asked)
    assert ref["status"] == "ok" and ref["e_t"] > 0 and ref["e_align"] > 0 and "ate_rmse" not in ref
    by_name = slamrun("evaluate", "--gt", sync, "--json", est)
    by_content = slamrun("evaluate", "--gt", renamed, "--json", est)
    assert by_name.returncode == by_content.returncode == 0, (by_name.stderr, by_content.stderr)
    assert json_rows(by_name) == json_rows(by_content) == [ref]
    assert by_name.stderr == "" and "TUM-Mono's ground truth" in by_content.stderr
    assert str(renamed) in by_content.stderr and "--metric ate" in by_content.stderr
    ate = slamrun("evaluate", "--gt", renamed, "--metric", "ate", "--json", est)  # its poses only, as before
    assert ate.returncode == 0 and json_rows(ate)[0]["ate_n"] == 24 and "e_t" not in json_rows(ate)[0]


def test_recognising_a_renamed_groundtruthsync_keeps_evaluate_lean(tum_mono_sequence, tmp_path):
    """Telling TUM-Mono's ground truth by its content loads no layout, no OpenCV, no PyYAML."""
    from tests.test_layout import loaded_by_evaluate

    sync, est = tum_mono_sequence
    renamed = tmp_path / "gt.txt"
    shutil.copyfile(sync, renamed)
    stdout, loaded = loaded_by_evaluate("--gt", str(renamed), str(est))
    assert "e_t=" in stdout and loaded == [], (stdout, loaded)


def nan_rows(gt: Path, out: Path, rows) -> Path:
    """`gt` with the poses of `rows` (0-based) written as NaN."""
    lines = gt.read_text().splitlines()
    for i in rows:
        lines[i] = lines[i].split()[0] + " NaN NaN NaN NaN NaN NaN NaN"
    out.write_text("\n".join(lines) + "\n")
    return out


@pytest.mark.parametrize(
    ("rows", "metrics"),
    [
        (range(0), ("ate", "rpe")),  # a plain TUM file
        (range(15, 45), ("tum-mono",)),  # poses at the start and the end, NaN rows between: TUM-Mono's shape
        (range(0, 5), ("ate", "rpe")),  # NaN rows at the start: a tracker's lost poses, not TUM-Mono's
        ((3, 17, 41, 52), ("ate", "rpe")),  # dropouts here and there
        (range(40, 60), ("ate", "rpe")),  # poses at the start only
        (range(10, 25), ("ate", "rpe")),  # a gap in the first half: the middle row has a pose
    ],
)
def test_a_tum_files_default_metrics_follow_its_nan_rows(loop, tmp_path, rows, metrics):
    """A TUM file is TUM-Mono's ground truth by its content when the rows with a pose lie in its first and its last
    half with NaN rows between them (over the middle row); any other TUM file is evaluated with ATE and RPE."""
    from slamrun.datasets.groundtruth import open_groundtruth

    gt, _ = loop
    gt = nan_rows(gt, tmp_path / "gt_nan.txt", rows)
    assert open_groundtruth(gt).default_metrics == metrics
    assert open_groundtruth(gt, "tum").default_metrics == ("ate", "rpe")  # a format given wins
    assert open_groundtruth(gt, None, ("ate",)).default_metrics == ("ate", "rpe")  # read as TUM: NaN rows dropped


def test_a_layouts_file_in_no_format_still_names_its_folder_without_a_metric(loop, tmp_path):
    """TartanAir's pose_left.txt (7 numbers a row, no time) without --metric, now read as TUM: the reader's error
    and TartanAir's note naming the folder form, in one line (as with a TUM-Mono read before)."""
    gt, est = loop
    poses = tmp_path / "P000" / "pose_left.txt"
    poses.parent.mkdir()
    poses.write_text("".join(" ".join(line.split()[1:]) + "\n" for line in gt.read_text().splitlines()))
    for metric in ([], ["--metric", "ate"]):
        out = slamrun("evaluate", "--gt", poses, *metric, est)
        assert out.returncode == 1 and "Traceback" not in out.stderr and len(out.stderr.splitlines()) == 1
        assert "7 values, expected 8" in out.stderr and f"--gt {poses.parent}" in out.stderr, out.stderr


def test_one_reader_choice_every_command_the_same_formats(shared_data, tmp_path):
    """One function picks a trajectory's reader, from a format name or the file's first row (evo's file_interface
    model): the real KITTI, EuRoC and TUM files of evo's test data are told apart, `evaluate --est-format auto` reads
    each as its own format with the figures of the format named, and `evaluate` and `import` offer the same formats."""
    import argparse

    from slamrun.cli import _parser as build_parser
    from slamrun.core.formats import FORMATS, RECOGNISED, recognise

    evo = shared_data / "evo_test_data"
    assert [recognise(evo / f) for f in ("KITTI_00_ORB.txt", "V102_groundtruth.csv", "fr2_desk_ORB.txt")] == [
        "kitti", "euroc", "tum",
    ]  # fmt: skip
    cases = [  # ground truth, estimate, its format, what else the files need
        ("KITTI_00_gt.txt", "KITTI_00_ORB.txt", "kitti", ["--times", evo / "KITTI_00_gt_times.txt"]),
        ("V102_groundtruth.csv", "V102_groundtruth.csv", "euroc", []),
        ("fr2_desk_groundtruth.txt", "fr2_desk_ORB.txt", "tum", []),
    ]
    for gt, est, fmt, extra in cases:
        named = slamrun("evaluate", "--gt", evo / gt, "--est-format", fmt, *extra, "--json", evo / est)
        told = slamrun("evaluate", "--gt", evo / gt, "--est-format", "auto", *extra, "--json", evo / est)
        assert named.returncode == told.returncode == 0, (fmt, named.stderr, told.stderr)
        assert json_rows(named) == json_rows(told) and json_rows(told)[0]["status"] == "ok", fmt
    parser = build_parser()
    subs = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices

    def offered(command: str, flag: str) -> list[str]:
        return next(a for a in subs[command]._actions if flag in a.option_strings).choices

    assert offered("evaluate", "--est-format") == offered("import", "--format") == [*FORMATS, RECOGNISED]


def test_an_unreadable_estimate_is_named_once_on_its_line(shared_data):
    """A KITTI pose file read as TUM: its line names the file once, then the line of the file and what was wrong."""
    evo = shared_data / "evo_test_data"
    est = evo / "KITTI_00_ORB.txt"
    out = slamrun("evaluate", "--gt", evo / "fr2_desk_groundtruth.txt", est)
    assert out.returncode == 1, out.stderr
    (line,) = out.stdout.splitlines()
    assert line.startswith(f"{est}: unreadable (line 1: 12 values, expected 8") and line.count(str(est)) == 1, line
