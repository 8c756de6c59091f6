"""TUM-Mono metrics against values built independently (known Sim(3) transforms), ATE against evo."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from slamrun.core.evaluation import tum_mono, tum_mono_file
from slamrun.core.trajectory import Trajectory, from_arrays, read_tum
from slamrun.results.vocabulary import EvalStatus
from tests.conftest import SHARED_DATA as DATA


def ground_truth(n: int = 400, seed: int = 0, nan_middle: bool = True) -> Trajectory:
    """A loop-like path with GT only in the first and last 20 %, as in groundtruthSync.txt."""
    t = 1000.0 + np.arange(n) * 0.05
    phase = np.linspace(0, 2 * np.pi, n)
    pos = np.column_stack([np.cos(phase) * 2, np.sin(phase) * 1.5, 0.3 * np.sin(3 * phase)])
    pos += np.random.default_rng(seed).normal(scale=0.02, size=pos.shape)
    quat = Rotation.from_euler("zyx", np.column_stack([phase, 0.1 * np.sin(phase), 0.05 * phase])).as_quat()
    if nan_middle:
        mid = slice(int(0.2 * n), int(0.8 * n))
        pos[mid] = np.nan
        quat[mid] = np.nan
    return Trajectory(t, pos, quat)


def sim3(scale: float, rotvec, trans) -> tuple[float, np.ndarray, np.ndarray]:
    return scale, Rotation.from_rotvec(rotvec).as_matrix(), np.asarray(trans, float)


def inverse_apply(s: float, r: np.ndarray, t: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Points p with s R p + t = x."""
    return (x - t) @ r / s


def estimate_from(gt: Trajectory, est_pos: np.ndarray, keep: np.ndarray | None = None) -> Trajectory:
    keep = np.ones(len(gt), bool) if keep is None else keep
    quat = np.tile([0, 0, 0, 1.0], (int(keep.sum()), 1))
    return from_arrays(gt.timestamps[keep], est_pos[keep], quat)


def test_exact_similarity_gives_zero_errors():
    gt = ground_truth(nan_middle=False)
    s, r, t = sim3(3.7, [0.3, -1.2, 0.5], [5, -2, 1])
    est = estimate_from(gt, inverse_apply(s, r, t, gt.positions))
    res = tum_mono(gt, est)
    assert res.status is EvalStatus.ok
    for name in ("e_t", "e_r", "e_align", "e_start", "e_end", "e_rmse"):
        assert getattr(res, name) == pytest.approx(0, abs=1e-9), name
    assert res.e_s == pytest.approx(1, abs=1e-12)


def test_known_drift_between_segments():
    """Start segment seen through S_a, end through S_b: e_s = s_a/s_b, e_r = angle(R_b R_a^T), e_t = |t(S_b S_a^-1)|."""
    gt = ground_truth()
    n = len(gt)
    sa = sim3(2.0, [0.1, 0.2, -0.3], [1, 2, 3])
    sb = sim3(2.5, [0.1, 0.2, -0.3 + np.radians(7)], [1.5, 1.0, 3.2])
    est_pos = np.empty_like(gt.positions)
    half = n // 2
    est_pos[:half] = inverse_apply(*sa, gt.positions[:half])
    est_pos[half:] = inverse_apply(*sb, gt.positions[half:])
    est_pos[np.isnan(est_pos)] = 0.0  # the middle: any finite positions
    est = estimate_from(gt, est_pos)
    res = tum_mono(gt, est)
    assert res.status is EvalStatus.ok
    assert res.e_s == pytest.approx(2.0 / 2.5, rel=1e-9)
    expected_r = np.degrees(Rotation.from_matrix(sb[1] @ sa[1].T).magnitude())
    assert res.e_r == pytest.approx(expected_r, rel=1e-9)
    # S_b S_a^-1 translation, written out independently: t_b - (s_b/s_a) R_b R_a^T t_a
    t_drift = sb[2] - (sb[0] / sa[0]) * sb[1] @ sa[1].T @ sa[2]
    assert res.e_t == pytest.approx(np.linalg.norm(t_drift), rel=1e-9)
    assert res.e_start == pytest.approx(0, abs=1e-9) and res.e_end == pytest.approx(0, abs=1e-9)
    # e_align over all estimated positions, computed point by point
    d = [(sb[0] * sb[1] @ p + sb[2]) - (sa[0] * sa[1] @ p + sa[2]) for p in est.positions]
    assert res.e_align == pytest.approx(np.sqrt(np.mean(np.sum(np.square(d), axis=1))), rel=1e-9)
    assert res.e_rmse > 0.01
    assert res.e_s_sym == pytest.approx(1.25)


def test_noise_gives_segment_rmse():
    gt = ground_truth(nan_middle=False)
    noise = np.random.default_rng(5).normal(scale=0.01, size=gt.positions.shape)
    res = tum_mono(gt, estimate_from(gt, gt.positions + noise))
    assert 0.005 < res.e_start < 0.02 and 0.005 < res.e_end < 0.02


def test_segment_split_follows_gt_rows():
    """With n GT rows, start = rows 1..floor(n/2), end = rows ceil(n/2)..n (odd n shares the middle row)."""
    gt = ground_truth(n=401, nan_middle=False)
    keep = np.zeros(401, bool)
    keep[[198, 199, 200]] = True  # 1-based rows 199..201: only row 201 is in both segments
    keep[[0, 1, 2, 398, 399, 400]] = True
    res = tum_mono(gt, estimate_from(gt, gt.positions, keep))
    assert res.status is EvalStatus.ok


def test_failure_cases():
    gt = ground_truth()
    ok = estimate_from(gt, np.nan_to_num(gt.positions))
    assert tum_mono(gt, ok).status is EvalStatus.ok
    empty = Trajectory(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 4)))
    assert tum_mono(gt, empty).status is EvalStatus.empty
    with_nan = np.nan_to_num(gt.positions)
    with_nan[5, 1] = np.nan
    raw = Trajectory(gt.timestamps, with_nan, np.tile([0, 0, 0, 1.0], (len(gt), 1)))
    assert tum_mono(gt, raw).status is EvalStatus.nan  # NaN in the arrays
    read = estimate_from(gt, with_nan)  # a reader drops the row and counts it ...
    assert len(read) == len(gt) - 1 and read.report.n_nonfinite_dropped == 1
    assert tum_mono_file(gt, read).status is EvalStatus.nan  # ... and the benchmark rejects such a file
    shifted = from_arrays(ok.timestamps + 0.0011, ok.positions, ok.quaternions)
    res = tum_mono(gt, shifted)
    assert res.status is EvalStatus.unassociated and np.isnan(res.e_t)
    within = from_arrays(ok.timestamps + 0.0009, ok.positions, ok.quaternions)
    assert tum_mono(gt, within).status is EvalStatus.ok
    start_only = np.arange(len(gt)) < len(gt) // 2
    res = tum_mono(gt, estimate_from(gt, np.nan_to_num(gt.positions), start_only))
    assert res.status is EvalStatus.incomplete
    assert res.to_dict()["e_t"] is None and res.to_dict()["status"] == "incomplete"
    middle_only = (np.arange(len(gt)) > 100) & (np.arange(len(gt)) < 300)
    assert tum_mono(gt, estimate_from(gt, np.nan_to_num(gt.positions), middle_only)).status is EvalStatus.incomplete


def test_backward_order_does_not_matter():
    gt = ground_truth()
    est = estimate_from(gt, np.nan_to_num(gt.positions) * 2 + 1)
    rev = from_arrays(est.timestamps[::-1], est.positions[::-1], est.quaternions[::-1])
    assert tum_mono(gt, est) == tum_mono(gt, rev)


def test_real_backward_file_evaluates_against_its_own_segments(shared_data):
    """A real DSO backward file: GT = its own poses with NaN in the middle gives zero segment errors."""
    est = read_tum(DATA / "study_trajectories" / "dso_bw__sequence_47_9.txt")
    n = len(est)
    gt_pos = est.positions.copy()
    gt_pos[int(0.2 * n) : int(0.8 * n)] = np.nan
    gt = Trajectory(est.timestamps, gt_pos, est.quaternions)
    res = tum_mono(gt, est)
    assert res.status is EvalStatus.ok
    assert res.e_start == pytest.approx(0, abs=1e-9) and res.e_s == pytest.approx(1, abs=1e-9)


def test_evaluate_cli_many_files_json(tmp_path, capsys):
    import json

    from slamrun.cli import main
    from slamrun.core.trajectory import write_tum

    gt = ground_truth()
    np.savetxt(tmp_path / "gt.txt", np.column_stack([gt.timestamps, gt.positions, gt.quaternions]))
    write_tum(tmp_path / "good.txt", estimate_from(gt, np.nan_to_num(gt.positions) * 2))
    (tmp_path / "bad.txt").write_text("1 2 3\n")
    write_tum(tmp_path / "empty.txt", estimate_from(gt, gt.positions, np.zeros(len(gt), bool)))
    files = [str(tmp_path / n) for n in ("good.txt", "bad.txt", "empty.txt")]
    assert main(["evaluate", "--gt", str(tmp_path / "gt.txt"), "--json", *files]) == 1  # 2 files not evaluated
    said = capsys.readouterr()
    assert "2 of 3 file(s) could not be evaluated" in said.err
    out = [json.loads(line) for line in said.out.splitlines()]
    assert [o["status"] for o in out] == ["ok", "unreadable", "empty"]
    assert out[0]["e_s"] == pytest.approx(1.0) and out[0]["e_align"] == pytest.approx(0, abs=1e-9)
    assert out[1]["e_t"] is None and "bad.txt:1" in out[1]["detail"]
    assert {"file", "status", "e_t", "e_r", "e_s", "e_align", "e_start", "e_end", "e_rmse", "n_poses"} <= set(out[0])


def reference_tum_mono(gt: Trajectory, est: Trajectory) -> tuple[float, ...]:
    """The definition in docs/tum-mono.md written plainly (masks, three separate fits), for cross-checking
    the batched implementation. Returns (e_t, e_r, e_s, e_align, e_start, e_end, e_rmse)."""
    from slamrun.core.alignment import align_sim3, rmse, rotation_angle_deg

    dist = np.abs(gt.timestamps[None, :] - est.timestamps[:, None])
    match = dist.argmin(axis=1)
    n = len(gt)
    t = est.timestamps
    valid = np.isfinite(gt.positions[match]).all(axis=1)
    in_start = valid & (t >= gt.timestamps[0]) & (t <= gt.timestamps[n // 2 - 1])
    in_end = valid & (t >= gt.timestamps[(n + 1) // 2 - 1]) & (t <= gt.timestamps[-1])
    p, g = est.positions, gt.positions[match]
    s, e = align_sim3(p[in_start], g[in_start]), align_sim3(p[in_end], g[in_end])
    both = in_start | in_end
    u = align_sim3(p[both], g[both])
    drift = e.matrix() @ np.linalg.inv(s.matrix())
    return (
        float(np.linalg.norm(drift[:3, 3])),
        rotation_angle_deg(e.rotation @ s.rotation.T),
        s.scale / e.scale,
        rmse(e.apply(p), s.apply(p)),
        rmse(s.apply(p[in_start]), g[in_start]),
        rmse(e.apply(p[in_end]), g[in_end]),
        rmse(u.apply(p[both]), g[both]),
    )


@pytest.mark.parametrize("seed", range(12))
def test_agrees_with_the_plain_definition(seed):
    """Random drifts, gaps and timestamp jitter; odd seeds use a fully finite GT with an even row count,
    where the middle row belongs to both segments (the union must not count it twice)."""
    rng = np.random.default_rng(seed)
    n = 2 * int(rng.integers(40, 300))
    gt = ground_truth(n, seed, nan_middle=seed % 2 == 0)
    drift = np.cumsum(rng.normal(scale=0.01, size=(n, 3)), axis=0)
    s, r, tr = sim3(rng.uniform(0.2, 5), rng.normal(size=3), rng.normal(size=3))
    est_pos = inverse_apply(s, r, tr, np.nan_to_num(ground_truth(n, seed, nan_middle=False).positions) + drift)
    keep = rng.random(n) < 0.8
    keep[[0, n // 2 - 1, n // 2, n - 1]] = True
    times = gt.timestamps + rng.uniform(-4e-4, 4e-4, n) * (seed % 3 == 0)
    est = from_arrays(times[keep], est_pos[keep], np.tile([0, 0, 0, 1.0], (int(keep.sum()), 1)))
    res = tum_mono(gt, est)
    assert res.status is EvalStatus.ok
    got = (res.e_t, res.e_r, res.e_s, res.e_align, res.e_start, res.e_end, res.e_rmse)
    np.testing.assert_allclose(got, reference_tum_mono(gt, est), rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("which", ["gt_start", "gt_end", "est_start", "est_end"])
def test_a_segment_at_one_point_is_status_nan_without_warnings(which):
    import warnings

    gt = ground_truth(200)
    est_pos = np.nan_to_num(gt.positions).copy()
    gt_pos = gt.positions.copy()
    seg = slice(0, 40) if which.endswith("start") else slice(160, 200)  # the whole GT segment
    (gt_pos if which.startswith("gt") else est_pos)[seg] = [1.0, 2.0, 3.0]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = tum_mono(Trajectory(gt.timestamps, gt_pos, gt.quaternions), estimate_from(gt, est_pos))
    assert res.status is EvalStatus.nan and np.isnan(res.e_t)


def test_evaluation_on_every_core_gives_the_same_numbers_in_input_order(tmp_path):
    """Many files (good, noisy, unreadable, NaN-holding, empty) through 1 and 3 worker processes."""
    from slamrun.core.batch_eval import evaluate_files
    from slamrun.core.trajectory import write_tum

    gt = ground_truth()
    rng = np.random.default_rng(5)
    paths = []
    for i in range(150):
        path = tmp_path / f"t{i:03d}.txt"
        kind = i % 10
        if kind == 7:
            path.write_text("1 2 3\n")
        elif kind == 8:
            pos = np.nan_to_num(gt.positions) * 1.5
            rows = np.column_stack([gt.timestamps, pos, np.tile([0, 0, 0, 1.0], (len(gt), 1))])
            rows[3, 2] = np.nan
            np.savetxt(path, rows)
        elif kind == 9:
            path.write_text("")
        else:
            noisy = np.nan_to_num(gt.positions) * (1 + i) + rng.normal(scale=0.01 * kind, size=gt.positions.shape)
            write_tum(path, estimate_from(gt, noisy))
        paths.append(path)
    one = list(evaluate_files(gt, paths, jobs=1))
    many = list(evaluate_files(gt, paths, jobs=3))
    assert [d["file"] for d in many] == [str(p) for p in paths]
    assert json_equal(one, many)
    assert {d["status"] for d in one} == {"ok", "unreadable", "nan", "empty"}


def json_equal(a, b) -> bool:
    import json

    return json.dumps(a, sort_keys=True) == json.dumps(b, sort_keys=True)


def test_many_estimates_at_once_give_each_file_its_own_result(monkeypatch):
    """tum_mono_many against tum_mono_file one by one: the usual estimates evaluated together, every other one
    (NaN-holding, empty, unassociated, incomplete, a segment at one point, a pose in both segments) with its own
    status and detail; the same figures to rounding, in order."""
    from slamrun.core import evaluation

    gt = ground_truth(400)
    base = np.nan_to_num(gt.positions)
    rng = np.random.default_rng(11)
    ests, usual = [], []
    for i in range(8):  # the usual case: scale, noise, dropped frames, jittered times
        keep = rng.random(len(gt)) < 0.9
        keep[[0, len(gt) - 1]] = True
        pos = inverse_apply(*sim3(0.5 + i, rng.normal(size=3), rng.normal(size=3)), base)
        pos += np.cumsum(rng.normal(scale=0.002 * i, size=pos.shape), axis=0)
        est = estimate_from(gt, pos, keep)
        if i % 2:
            est = est.with_timestamps(est.timestamps + rng.uniform(-9e-4, 9e-4, len(est)))
        ests.append(est)
        usual.append(True)
    nan_pos = base.copy()
    nan_pos[5, 1] = np.nan
    at_one_point = base.copy()
    at_one_point[:80] = [1.0, 2.0, 3.0]
    odd = [
        estimate_from(gt, nan_pos),  # a row dropped by the reader: nan
        Trajectory(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 4))),  # empty
        from_arrays(gt.timestamps + 0.0011, base, np.tile([0, 0, 0, 1.0], (len(gt), 1))),  # unassociated
        estimate_from(gt, base, np.arange(len(gt)) < len(gt) // 2),  # incomplete
        estimate_from(gt, at_one_point),  # degenerate start segment: nan
    ]
    full_gt = ground_truth(400, nan_middle=False)  # even row count, finite middle row: a pose in both segments
    for k, est in enumerate(odd):
        ests.insert(2 * k + 1, est)
        usual.insert(2 * k + 1, False)

    calls = []
    plain = evaluation.tum_mono
    monkeypatch.setattr(evaluation, "tum_mono", lambda g, e: calls.append(e) or plain(g, e))
    got = evaluation.tum_mono_many(gt, ests)
    assert not any(any(e is c for c in calls) for e, u in zip(ests, usual, strict=True) if u), "not batched"
    monkeypatch.setattr(evaluation, "tum_mono", plain)
    shared = evaluation.tum_mono_many(full_gt, ests[:1])
    pairs = [*zip(got, [tum_mono_file(gt, e) for e in ests], strict=True), (shared[0], tum_mono(full_gt, ests[0]))]
    for res, want in pairs:
        assert (res.status, res.detail, res.n_poses) == (want.status, want.detail, want.n_poses)
        a, b = res.to_dict(), want.to_dict()
        for name in ("e_t", "e_r", "e_s", "e_align", "e_start", "e_end", "e_rmse"):
            if b[name] is None:
                assert a[name] is None, name
            else:
                assert a[name] == pytest.approx(b[name], rel=1e-9, abs=1e-12), name
    assert [r.status for r in got].count(EvalStatus.ok) == 8
