"""Settings always apply (issue 62): changing a dataset's `rpe:` or `min_coverage` after its runs finished, then
`slamrun campaign` again, re-evaluates every finished run from its stored trajectory (no method runs again); the
figures equal `slamrun evaluate` with the new settings, the plan and the dry run count the runs to re-evaluate, and
the report's spec as run and its figures agree. `slamrun report` does the same for runs of an older evaluation."""

from __future__ import annotations

import contextlib
import io
import json
import sqlite3

import pandas as pd
import pytest
import yaml

from slamrun.cli import main
from slamrun.datasets.make_synthetic import generate
from tests.conftest import fake_method, write_spec


def cli(*args) -> str:
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main([*map(str, args)]) == 0
    return buf.getvalue()


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    root = tmp_path_factory.mktemp("reevaluate")
    data = root / "data"
    for name, seed in (("seq_a", 1), ("seq_b", 2)):
        generate(data / name, frames=80, seed=seed, size=(160, 120), layout="euroc")
    methods = [
        fake_method(label="every", extra=["--noise", "0.01", "--vary"]),
        fake_method(label="fifth", extra=["--noise", "0.01", "--vary", "--every", "5"]),
    ]
    datasets = [{"name": "room", "path": str(data), "sequences": ["seq_a", "seq_b"], "layout": "euroc"}]
    spec = write_spec(root, data, methods, datasets=datasets, trials=1)
    assert main(["campaign", str(spec)]) == 0
    before = pd.read_csv(root / "results" / "results.csv")
    return root, spec, data, before


def test_changed_rpe_and_min_coverage_apply_to_the_finished_runs(finished):
    root, spec, data, before = finished
    assert before.status.eq("done").all() and before.rpe_interval.eq("1 s").all()
    raw = yaml.safe_load(spec.read_text())
    raw["datasets"][0] |= {"rpe": {"delta": 2, "unit": "s"}, "min_coverage": 0.5}
    spec.write_text(yaml.safe_dump(raw))
    plan = cli("plan", spec)
    assert "0 run(s) to run of 8" in plan and "8 run(s) to re-evaluate" in plan, plan
    out = cli("campaign", spec)
    assert "re-evaluated 8 finished run(s)" in out
    after = pd.read_csv(root / "results" / "results.csv")
    assert after.attempts.tolist() == before.attempts.tolist()  # no method ran again
    assert after.rpe_interval.eq("2 s").all()
    # each figure is what `slamrun evaluate` gives the stored trajectory with the new settings
    for row in after.itertuples():
        seq = data / row.sequence
        line = cli(
            "evaluate",
            "--gt",
            seq,
            "--metric",
            "ate",
            "--metric",
            "rpe",
            "--delta",
            "2",
            "--json",
            f"{row.run_dir}/trajectory.txt",
        )
        figures = json.loads(line)
        assert row.rpe_t_rmse == pytest.approx(figures["rpe_t_rmse"], rel=1e-9), row.key
        assert row.ate_rmse == pytest.approx(figures["ate_rmse"], rel=1e-9)
    assert not after.rpe_t_rmse.equals(before.rpe_t_rmse)
    # min_coverage 0.5: every 5th frame of what it was given is 20 %: lost, said in the report
    fifth = after[after.method == "fifth"]
    assert fifth.status.eq("failed").all() and fifth.failure.eq("lost").all()
    assert fifth.message.str.contains("under the dataset's min_coverage 0.5").all()
    assert after[after.method == "every"].status.eq("done").all()
    html = cli("report", root / "results") and (root / "results" / "report" / "index.html").read_text()
    assert "4 run(s) gave poses for fewer than min_coverage 0.5" in html
    assert "No coverage threshold" not in html
    # a campaign again: nothing left to re-evaluate, nothing to run
    assert "to re-evaluate" not in cli("plan", spec)


def test_runs_of_an_older_evaluation_are_evaluated_again_by_report(finished):
    root, spec, _, _ = finished
    results = root / "results"
    db = sqlite3.connect(results / "ledger.sqlite")
    with db:
        db.execute("UPDATE runs SET eval_settings = NULL, rpe_t_rmse = 123.0 WHERE method = 'every'")
    db.close()
    assert "4 run(s) to re-evaluate" in cli("plan", spec)
    out = cli("report", results)
    assert "re-evaluated 4 finished run(s)" in out
    after = pd.read_csv(results / "results.csv")
    assert (after.rpe_t_rmse < 1).all()
