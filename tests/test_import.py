"""Published trajectories imported into a campaign: the study's real files (../shared/data/study_trajectories), as a
folder and as split archives like the study's database, evaluated by the campaign's own code against a synthetic
TUM-Mono ground truth at the real files' frame times; one transaction, idempotent, never overwriting."""

from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from slamrun.cli import main
from slamrun.datasets.make_synthetic import generate
from slamrun.engine.ledger import Ledger

SEQUENCES = ("47", "48", "49")


def frame_times(study: Path, number: str) -> np.ndarray:
    """The union of the study files' timestamps of a sequence: frame times of the real sequence."""
    times: set[float] = set()
    for f in study.glob(f"*_sequence_{number}_*.txt"):
        times |= set(np.round(np.loadtxt(f, ndmin=2)[:, 0], 6).tolist())
    return np.array(sorted(times))


def sequence_at(folder: Path, times: np.ndarray, seed: int) -> Path:
    """A small synthetic TUM-Mono sequence whose frames are at `times` (its ground truth too)."""
    generate(folder, frames=len(times), seed=seed, size=(80, 60))
    rows = (folder / "times.txt").read_text().splitlines()
    (folder / "times.txt").write_text(
        "".join(f"{r.split()[0]} {t:.6f} {r.split()[2]}\n" for r, t in zip(rows, times, strict=True))
    )
    for name in ("groundtruthSync.txt", "groundtruth_full.txt"):
        lines = (folder / name).read_text().splitlines()
        (folder / name).write_text(
            "".join(f"{t:.6f} {' '.join(ln.split()[1:])}\n" for ln, t in zip(lines, times, strict=True))
        )
    return folder


@pytest.fixture(scope="module")
def campaign(shared_data, tmp_path_factory) -> Path:
    """A campaign (one fake method, forward) on sequences 47-49 at the study files' frame times."""
    import yaml

    from slamrun.engine.campaign import run_campaign
    from slamrun.engine.spec_file import load_spec
    from tests.conftest import fake_method

    root = tmp_path_factory.mktemp("import")
    study = shared_data / "study_trajectories"
    for i, number in enumerate(SEQUENCES):
        sequence_at(root / "data" / f"sequence_{number}", frame_times(study, number), seed=i)
    spec = {
        "name": "imp",
        "results": str(root / "results"),
        "cache": str(root / "cache"),
        "datasets": [
            {"name": "tum-mono", "path": str(root / "data"), "sequences": [f"sequence_{n}" for n in SEQUENCES]}
        ],
        "methods": [fake_method(label="dso")],
        "directions": ["backward"],
        "trials": 1,
        "timeout_s": 60,
        "lanes": 2,
        "report": False,
    }
    (root / "spec.yaml").write_text(yaml.safe_dump(spec))
    run_campaign(load_spec(root / "spec.yaml"), on_event=None, log=lambda *a: None)
    return root / "results"


def split_archives(study: Path, dest: Path, code: str, direction: str, part_size: int = 60_000) -> Path:
    """The study's database layout: `<code>_<dir>.zip` holding `<code>_<dir>/sequence_SS_R.txt`, split into
    `.001`, `.002`, ... parts; returns the first part."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        for f in sorted(study.glob(f"{code}_{direction}__sequence_*.txt")):
            zf.write(f, f"{code}_{direction}/{f.name.split('__', 1)[1]}")
    data = buf.getvalue()
    dest.mkdir(parents=True, exist_ok=True)
    for i in range(0, len(data), part_size):
        (dest / f"{code}_{direction}.zip.{i // part_size + 1:03d}").write_bytes(data[i : i + part_size])
    assert (dest / f"{code}_{direction}.zip.002").exists()  # really split
    return dest / f"{code}_{direction}.zip.001"


def rows_of(results: Path, label: str) -> list[dict]:
    ledger = Ledger(results / "ledger.sqlite", read_only=True)
    try:
        return [r for r in ledger.rows() if r["method"] == label]
    finally:
        ledger.close()


def test_the_studys_files_import_as_runs_evaluated_by_the_campaigns_code(campaign, shared_data, tmp_path):
    study = shared_data / "study_trajectories"
    first = split_archives(study, tmp_path / "db", "dso", "bw")
    assert main(["import", str(first), "--campaign", str(campaign), "--as", "study:dso"]) == 0
    runs = rows_of(campaign, "study:dso")
    assert sorted((r["sequence"], r["direction"], r["trial"]) for r in runs) == [
        ("sequence_47", "backward", 9),
        ("sequence_48", "backward", 0),
        ("sequence_48", "backward", 1),
    ]
    assert all(r["status"] == "done" and r["eval_status"] == "ok" and r["e_align"] is not None for r in runs)
    record = json.loads((Path(runs[0]["run_dir"]) / "run.json").read_text())
    assert record["method_name"] == "imported" and len(record["imported"]["sha256"]) == 64
    assert record["imported"]["source"].endswith(".zip.001:dso_bw/sequence_47_9.txt")
    assert "wall_s" not in record and "fps" not in record  # no resources: nothing was run here

    # the folder of the study's own file names, another label; results.csv and the report carry both
    assert main(["import", str(study), "--campaign", str(campaign), "--as", "study:all"]) == 0
    labels = pd.read_csv(campaign / "results.csv").method.value_counts()
    assert labels["study:dso"] == 3 and labels["study:all"] == 12 and labels["dso"] == 3
    dsm = [r for r in rows_of(campaign, "study:all") if r["sequence"] == "sequence_47"]
    assert len(dsm) == 4  # dsm_bw 6, 7, 8 and dso_bw 9
    from slamrun.analysis.report import write_report

    html = write_report(campaign).read_text()
    assert "study:dso" in html and "Reproduction" in html


def test_importing_again_changes_nothing_and_nothing_is_overwritten(campaign, shared_data, tmp_path, capsys):
    study = shared_data / "study_trajectories"
    files = tmp_path / "files"
    files.mkdir()
    for f in study.glob("dyna_fw__*"):
        (files / f.name).write_bytes(f.read_bytes())
    assert main(["import", str(files), "--campaign", str(campaign), "--as", "study:dyna"]) == 0
    before = {r["key"]: r for r in rows_of(campaign, "study:dyna")}
    assert len(before) == 3
    capsys.readouterr()
    assert main(["import", str(files), "--campaign", str(campaign), "--as", "study:dyna"]) == 0
    assert "0 run(s) imported, 3 unchanged" in capsys.readouterr().out
    changed = files / "dyna_fw__sequence_49_2.txt"
    lines = changed.read_text().splitlines()
    changed.write_text("\n".join(lines[:-5]) + "\n")  # another file under the same run's name
    assert main(["import", str(files), "--campaign", str(campaign), "--as", "study:dyna"]) == 0
    assert "1 kept" in capsys.readouterr().out
    assert {r["key"]: r for r in rows_of(campaign, "study:dyna")} == before


def test_bad_input_is_named_and_nothing_is_imported_halfway(campaign, shared_data, tmp_path, capsys):
    study = shared_data / "study_trajectories"
    # a corrupt archive part
    first = split_archives(study, tmp_path / "db", "dsm", "bw")
    second = first.with_name("dsm_bw.zip.002")
    data = bytearray(second.read_bytes())
    data[100:400] = bytes(300)
    second.write_bytes(bytes(data))
    assert main(["import", str(first), "--campaign", str(campaign), "--as", "study:dsm"]) == 1
    assert "dsm_bw.zip.001" in capsys.readouterr().err
    # a name that does not match the pattern, beside good files: nothing of the folder is imported
    folder = tmp_path / "mixed"
    folder.mkdir()
    for f in study.glob("cnn-svo_fw__*"):
        (folder / f.name).write_bytes(f.read_bytes())
    (folder / "cnn-svo_sequence_48.txt").write_bytes(b"1 0 0 0 0 0 0 1\n")
    assert main(["import", str(folder), "--campaign", str(campaign), "--as", "study:cnn-svo"]) == 1
    assert "cnn-svo_sequence_48.txt" in capsys.readouterr().err
    # a trajectory of another sequence under this sequence's name
    (folder / "cnn-svo_sequence_48.txt").unlink()
    (folder / "cnn-svo_fw__sequence_47_0.txt").write_bytes((study / "cnn-svo_fw__sequence_48_7.txt").read_bytes())
    assert main(["import", str(folder), "--campaign", str(campaign), "--as", "study:cnn-svo"]) == 1
    err = capsys.readouterr().err
    assert "cnn-svo_fw__sequence_47_0.txt: not a trajectory of sequence_47" in err
    assert rows_of(campaign, "study:dsm") == [] and rows_of(campaign, "study:cnn-svo") == []
    assert not list((campaign / "runs").glob("study:dsm*")) and not list((campaign / "runs").glob("study:cnn-svo*"))
    # a sequence the campaign does not have is named and skipped; a folder that is no campaign is refused
    (folder / "cnn-svo_fw__sequence_47_0.txt").unlink()
    (folder / "cnn-svo_fw__sequence_12_0.txt").write_bytes(b"")
    assert main(["import", str(folder), "--campaign", str(campaign), "--as", "study:cnn-svo"]) == 0
    assert "skipped: " in capsys.readouterr().out and len(rows_of(campaign, "study:cnn-svo")) == 3
    assert main(["import", str(folder), "--campaign", str(tmp_path / "nothing"), "--as", "x"]) == 1
    assert "not a campaign's results folder" in capsys.readouterr().err and not (tmp_path / "nothing").exists()


def test_imported_runs_survive_a_resumed_campaign_and_a_lost_ledger(campaign, shared_data, tmp_path):
    from slamrun.engine.campaign import run_campaign
    from slamrun.engine.spec_file import load_spec

    study = shared_data / "study_trajectories"
    assert main(["import", str(study), "--campaign", str(campaign), "--as", "study:keep"]) == 0
    spec = load_spec(campaign / "spec.resolved.yaml")
    run_campaign(spec, on_event=None, log=lambda *a: None)  # the plan knows nothing of imports: they stay
    assert len(rows_of(campaign, "study:keep")) == 12
    (campaign / "ledger.sqlite").unlink()
    for extra in ("ledger.sqlite-wal", "ledger.sqlite-shm"):
        (campaign / extra).unlink(missing_ok=True)
    run_campaign(spec, on_event=None, log=lambda *a: None)
    assert len(rows_of(campaign, "study:keep")) == 12
