"""`slamrun evaluate --gt SEQUENCE_FOLDER` checks a campaign run's sequence by the data digest its run.json records
(the run key's `<sequence>@<data>`), not by the folder's name alone: a run of another sequence under the same folder
name is refused, the same sequence copied (or renamed) elsewhere is accepted; a run.json's values are quoted
bounded in length; a run.json that is not a run's record, or an older one without its digest, is said. Real
synthetic sequences, a real campaign of the fake method, `slamrun evaluate` as a separate process."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from slamrun.datasets.layouts import sequence_identity
from slamrun.datasets.make_synthetic import generate
from tests.conftest import fake_method, write_spec
from tests.test_evaluate_cli import json_rows, slamrun

HUGE = 1_000_000  # characters of a hostile run.json's field (the record stays under evaluate's 1 MiB bound)
QUOTED_MAX = 300  # the longest a quoted value of a run.json may be in a message


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, Path]:
    """Two synthetic sequences named alike (`seq`) of different seeds, a copy of the first elsewhere and under
    another name, and a campaign run of the fake method (the ground truth, a little noise) on the first."""
    from slamrun.engine.campaign import run_campaign
    from slamrun.engine.spec_file import load_spec

    root = tmp_path_factory.mktemp("digest")
    ours = generate(root / "ours" / "seq", frames=40, seed=1, size=(160, 120))
    other = generate(root / "other" / "seq", frames=40, seed=2, size=(160, 120))
    copy = shutil.copytree(ours, root / "copy" / "seq")
    renamed = shutil.copytree(ours, root / "renamed" / "seq_moved")
    method = fake_method(extra=["--noise", "0.01"])
    datasets = [{"name": "s", "path": str(ours.parent), "sequences": ["seq"]}]
    spec = write_spec(root, root, [method], datasets=datasets, directions=["forward"])
    res = run_campaign(load_spec(spec), log=lambda *a: None)
    (run_dir,) = {p.parent for p in (res.results_csv.parent / "runs").rglob("run.json")}
    assert (run_dir / "trajectory.txt").is_file()
    return {"ours": ours, "other": other, "copy": copy, "renamed": renamed, "run": run_dir, "root": root}


def a_run_with(runs, name: str, change) -> Path:
    """A copy of the campaign's run folder whose run.json is `change(record)` (a dict, or the file's text), and its
    trajectory.txt."""
    folder = runs["root"] / "edited" / name
    shutil.copytree(runs["run"], folder)
    record = json.loads((folder / "run.json").read_text())
    changed = change(record)
    (folder / "run.json").write_text(changed if isinstance(changed, str) else json.dumps(changed))
    return folder / "trajectory.txt"


def error_lines(out) -> list[str]:
    return [line for line in out.stderr.splitlines() if line.startswith("slamrun: error:")]


def test_a_run_on_another_sequence_of_the_same_folder_name_is_refused_naming_both_digests(runs):
    """Today's check by name let this through (`ok`, against the wrong ground truth): the run's recorded digest and
    the folder's differ, so it is refused in one line naming the run, the folder, both digests and --any-sequence."""
    traj = runs["run"] / "trajectory.txt"
    recorded = json.loads((runs["run"] / "run.json").read_text())["data"]
    theirs = sequence_identity(runs["other"])
    assert recorded == sequence_identity(runs["ours"]) != theirs  # the same folder name, other data
    out = slamrun("evaluate", "--gt", runs["other"], traj)
    assert out.returncode == 1 and out.stdout == "" and "Traceback" not in out.stderr
    (line,) = out.stderr.splitlines()
    assert line.startswith(f"slamrun: error: {traj}: ")
    assert str(runs["run"] / "run.json") in line and str(runs["other"]) in line
    assert f"'{recorded}'" in line and f"'{theirs}'" in line and "--any-sequence" in line
    assert len(line) < 1000
    forced = slamrun("evaluate", "--gt", runs["other"], "--any-sequence", "--json", traj)
    assert forced.returncode == 0 and [r["status"] for r in json_rows(forced)] == ["ok"], forced.stderr


def test_the_same_sequence_copied_or_renamed_elsewhere_is_accepted_with_the_same_figures(runs):
    """A digest is of the content, not of paths: the sequence copied elsewhere gives the original's figures; copied
    under another name too (its run named the other name: said in a note, evaluated)."""
    traj = runs["run"] / "trajectory.txt"
    original = slamrun("evaluate", "--gt", runs["ours"], "--json", traj)
    assert original.returncode == 0 and original.stderr == "", original.stderr
    copied = slamrun("evaluate", "--gt", runs["copy"], "--json", traj)
    assert copied.returncode == 0 and copied.stderr == "", copied.stderr
    assert json_rows(copied) == json_rows(original)
    renamed = slamrun("evaluate", "--gt", runs["renamed"], "--json", traj)
    assert renamed.returncode == 0 and json_rows(renamed) == json_rows(original), renamed.stderr
    (note,) = renamed.stderr.splitlines()
    assert note.startswith("slamrun: note: ") and "'seq'" in note and "'seq_moved'" in note and "same data" in note


@pytest.mark.parametrize("field", ["sequence", "data"])
def test_a_huge_field_of_run_json_is_quoted_cut_never_whole(runs, field):
    """A 1 MB sequence name or data digest in run.json (once echoed whole: a 1,000,209-byte message) is quoted by
    its start, said cut with its length; the run is refused all the same."""
    traj = a_run_with(runs, f"huge_{field}", lambda r: {**r, field: "x" * HUGE})
    out = slamrun("evaluate", "--gt", runs["other"], traj)
    assert out.returncode == 1 and out.stdout == "" and "Traceback" not in out.stderr
    (line,) = error_lines(out)
    assert len(out.stderr) < 1500, len(out.stderr)
    assert "'xxxxxxxx" in line and f"cut: {HUGE:,} characters" in line and "x" * (QUOTED_MAX + 1) not in line


def test_a_huge_sequence_name_on_the_same_data_is_said_bounded_and_evaluated(runs):
    traj = a_run_with(runs, "huge_name_same_data", lambda r: {**r, "sequence": "y" * HUGE})
    out = slamrun("evaluate", "--gt", runs["ours"], "--json", traj)
    assert out.returncode == 0 and [r["status"] for r in json_rows(out)] == ["ok"], out.stderr[:2000]
    (note,) = out.stderr.splitlines()
    assert len(note) < 1000 and f"cut: {HUGE:,} characters" in note and "y" * (QUOTED_MAX + 1) not in note


def test_an_older_run_without_its_digest_is_checked_by_name_and_says_so(runs):
    """A run.json without "data" (an older run): checked by its sequence's name, as before, and said; a huge name
    is quoted cut there too."""
    older = a_run_with(runs, "older", lambda r: {k: v for k, v in r.items() if k != "data"})
    out = slamrun("evaluate", "--gt", runs["other"], "--json", older)
    assert out.returncode == 0 and [r["status"] for r in json_rows(out)] == ["ok"], out.stderr
    (note,) = out.stderr.splitlines()
    assert note.startswith(f"slamrun: note: {older}: ") and "no data digest" in note and "name" in note
    renamed = slamrun("evaluate", "--gt", runs["renamed"], older)
    assert renamed.returncode == 1 and "of sequence 'seq', not of" in error_lines(renamed)[0]
    huge = a_run_with(
        runs, "older_huge", lambda r: {k: v for k, v in r.items() if k != "data"} | {"sequence": "z" * HUGE}
    )
    out = slamrun("evaluate", "--gt", runs["other"], huge)
    assert out.returncode == 1 and len(out.stderr) < 1500, len(out.stderr)
    assert f"cut: {HUGE:,} characters" in error_lines(out)[0]


@pytest.mark.parametrize(
    ("name", "text", "why"),
    [
        ("not_json", "{not json", "not JSON"),
        ("not_object", "[1, 2, 3]", "not a JSON object"),
        ("too_large", " " * (2**20 + 1), "a run's record is at most 1,048,576 bytes"),
    ],
    ids=["not_json", "not_object", "too_large"],
)
def test_a_run_json_that_is_no_runs_record_is_said_and_the_file_evaluated(runs, name, text, why):
    """run.json beside the file but no run's record: the file is evaluated as any file, and the note says that
    its sequence was not checked and why."""
    traj = a_run_with(runs, name, lambda r: text)
    out = slamrun("evaluate", "--gt", runs["other"], "--json", traj)
    assert out.returncode == 0 and [r["status"] for r in json_rows(out)] == ["ok"], out.stderr
    (note,) = out.stderr.splitlines()
    assert note.startswith(f"slamrun: note: {traj.parent / 'run.json'}: ") and why in note and "not checked" in note
