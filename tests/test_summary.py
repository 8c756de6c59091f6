"""One per-method summary: the terminal table, `slamrun status` and the report give the same counts and rates,
with infrastructure failures and unfinished runs out of every rate."""

from __future__ import annotations

import pandas as pd
import pytest

from slamrun.analysis.report import write_report
from slamrun.analysis.summary import method_summary
from slamrun.engine.progress import figures
from slamrun.results.summary import tally

# 6 done, 2 lost, 2 infra, 1 pending: the method's results are the 8 done or lost runs
STATES = [("done", None, "ok")] * 6 + [("failed", "lost", None)] * 2 + [("failed", "infra", None)] * 2
STATES += [("pending", None, None)]


def metrics(i: int) -> dict:
    return {"e_t": 0.1 * (i + 1), "e_r": 1.0, "e_s_sym": 1.1, "e_align": 0.01 * (i + 1), "e_rmse": 0.02}


def rows() -> list[dict]:
    return [
        {
            "key": f"k{i}",
            "method": "dso",
            "method_name": "dso",
            "sequence": f"sequence_{i:02d}",
            "direction": "forward",
            "trial": 0,
            "status": state,
            "failure": failure,
            "eval_status": eval_status,
            **(metrics(i) if state == "done" else {}),
        }
        for i, (state, failure, eval_status) in enumerate(STATES)
    ]


def results_table() -> pd.DataFrame:
    df = pd.DataFrame(rows())
    return df.assign(e_start=0.01, e_end=0.01)


def test_tally_leaves_infra_and_pending_out_of_the_rates():
    t = tally(STATES)
    assert (t.runs, t.done, t.failed, t.infra, t.pending, t.evaluated) == (11, 6, 2, 2, 1, 6)
    assert t.success_pct == pytest.approx(75.0) and t.failure_pct == pytest.approx(25.0)
    assert t.failures["lost"] == 2 and t.failures["crashed"] == 0


def test_terminal_table_status_and_report_agree(tmp_path):
    """The report used to divide method failures by every run (20 % here) while the terminal table said 75 %
    success (25 % failure): both now say 75 / 25, and so does status."""
    df = results_table()
    df.to_csv(tmp_path / "results.csv", index=False)

    terminal = method_summary(df).set_index("method").loc["dso"]
    assert terminal["success_pct"] == pytest.approx(75.0) and terminal["failure_pct"] == pytest.approx(25.0)
    assert (terminal["failed"], terminal["infra"], terminal["pending"], terminal["lost"]) == (2, 2, 1, 2)

    status = figures(rows(), {"lanes": 1, "started_at": 0.0}, now=1.0)
    assert status.per_group[0]["success_pct"] == pytest.approx(75.0)
    assert (status.done, status.failed, status.infra) == (6, 2, 2)

    write_report(tmp_path)
    report = pd.read_csv(tmp_path / "report" / "tables" / "failures.csv").set_index("method").loc["dso"]
    assert report["failure %"] == pytest.approx(25.0)
    assert report["success %"] == pytest.approx(75.0)
    assert (report["runs"], report["failed (method)"], report["infra"], report["lost"]) == (11, 2, 2, 2)


def test_medians_are_over_evaluated_runs_only():
    df = results_table()
    lost_with_poses = df["failure"] == "lost"
    df.loc[lost_with_poses, ["e_t", "eval_status"]] = [100.0, "ok"]  # a lost run that wrote poses
    assert method_summary(df).loc[0, "median_e_t"] == pytest.approx(0.35)  # median of 0.1 ... 0.6
