"""Import published trajectories into a campaign's ledger as runs of a method label (e.g. `study:dso`).

Sources are folders, zip files, or split zip archives (`X.zip.001`, `X.zip.002`, ... joined in order), as the
study published its database (`<code>_<fw|bw>/sequence_SS_R.txt`). Each file's name gives its sequence, direction
and trial (the study's pattern, or `--pattern` with the named groups `sequence`, `direction` and `trial`). Each run
is recorded like a campaign's own: a run folder with trajectory.txt and run.json (the source file, its SHA-256,
`imported: true`, no resources), evaluated by the same code against the campaign's ground truth.

An import is one transaction: every file is read and checked first, and any problem (a corrupt archive part, a
name that does not match, a trajectory of another sequence) stops it before anything is written. Re-importing the
same files changes nothing; a run that exists is never overwritten.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import tempfile
import time
import zipfile
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from runner.core import jsonio, metrics
from runner.core.trajectory import Trajectory, read_euroc_csv, read_kitti, read_tum, write_tum
from runner.datasets.layouts import open_sequence, sequence_identity
from runner.datasets.view import Direction
from runner.engine.execute import evaluate, foreign_timestamps_of
from runner.engine.folders import path_part_problem
from runner.engine.ledger import Ledger
from runner.engine.paths import RunPaths
from runner.engine.plan import RunKey
from runner.engine.spec import CampaignSpec, load_spec
from runner.errors import SlamRunError, TrajectoryFormatError
from runner.results.vocabulary import IMPORTED

STUDY_PATTERN = r"(?:^|/)[a-z0-9-]+_(?P<direction>fw|bw)(?:__|/)sequence_(?P<sequence>\d+)_(?P<trial>\d+)\.txt$"
DIRECTIONS = {
    "fw": Direction.forward,
    "forward": Direction.forward,
    "bw": Direction.backward,
    "backward": Direction.backward,
}


class ImportRefused(SlamRunError):
    """An import refused as a whole (nothing was written)."""


@dataclass
class ImportReport:
    imported: list[str] = field(default_factory=list)
    unchanged: list[str] = field(default_factory=list)  # the same file imported before
    kept: list[str] = field(default_factory=list)  # a run of that key exists from another file: not overwritten
    skipped: list[str] = field(default_factory=list)  # a sequence the campaign does not have


@dataclass(frozen=True)
class _Entry:
    source: str  # file, or archive:member
    sequence: str
    direction: Direction
    trial: int
    data: bytes

    @property
    def sha256(self) -> str:
        return hashlib.sha256(self.data).hexdigest()


def members(source: Path) -> Iterator[tuple[str, bytes]]:
    """(name, bytes) of every file of a folder, a zip, or a split zip (`.zip.001` first part)."""
    if source.is_dir():
        for p in sorted(source.rglob("*")):
            if p.is_file():
                yield str(p.relative_to(source)), p.read_bytes()
        return
    parts = split_parts(source)
    if parts is None:
        if not source.is_file():
            raise ImportRefused(f"{source}: not found; expected a folder, a zip or the first part of a split zip")
        if not zipfile.is_zipfile(source):  # a single trajectory file
            yield source.name, source.read_bytes()
            return
        parts = [source]
    with tempfile.TemporaryDirectory() as tmp:
        joined = Path(tmp) / "joined.zip"
        with open(joined, "wb") as out:
            for p in parts:
                with open(p, "rb") as f:
                    shutil.copyfileobj(f, out)
        try:
            with zipfile.ZipFile(joined) as zf:
                bad = zf.testzip()
                if bad is not None:
                    raise ImportRefused(f"{source}: member {bad} is corrupt (a damaged part of {len(parts)}?)")
                for info in zf.infolist():
                    if not info.is_dir():
                        yield info.filename, zf.read(info)
        except (zipfile.BadZipFile, EOFError, OSError) as exc:
            names = ", ".join(p.name for p in parts)
            raise ImportRefused(f"{source}: not a readable zip ({exc}); its parts: {names}") from None


def split_parts(source: Path) -> list[Path] | None:
    """The parts of a split archive, in order, from any of them (`name.zip.001`, `.002`, ...); None otherwise."""
    m = re.fullmatch(r"(.*)\.(\d{3})", source.name)
    if m is None:
        return None
    parts, i = [], 1
    while (p := source.with_name(f"{m.group(1)}.{i:03d}")).is_file():
        parts.append(p)
        i += 1
    if not parts:
        raise ImportRefused(f"{source}: no {m.group(1)}.001 beside it (the first part of the split archive)")
    return parts


def _sequence_name(raw: str, known: set[str]) -> str:
    """The campaign's name of a sequence: as written, or `sequence_SS` for a number."""
    if raw in known:
        return raw
    return f"sequence_{int(raw):02d}" if raw.isdigit() else raw


def read_entries(sources: list[Path], pattern: str, known: set[str]) -> tuple[list[_Entry], list[str]]:
    """Every trajectory file of the sources with its sequence, direction and trial; files whose names do not
    match are errors (all named at once), files of sequences not in `known` are skipped (named)."""
    rx = re.compile(pattern)
    for group in ("sequence", "direction", "trial"):
        if group not in rx.groupindex:
            raise ImportRefused(f"--pattern {pattern!r}: needs the named group (?P<{group}>...)")
    entries, bad, skipped = [], [], []
    for source in sources:
        for name, data in members(Path(source)):
            if Path(name).name.startswith(".") or name.lower().endswith(("readme", ".md")):
                continue
            m = rx.search(name)
            where = (
                f"{source}:{name}" if Path(source).is_file() and Path(source).name != name else str(Path(source) / name)
            )
            if m is None or m.group("direction").lower() not in DIRECTIONS or not m.group("trial").isdigit():
                bad.append(where)
                continue
            sequence = _sequence_name(m.group("sequence"), known)
            if sequence not in known:
                skipped.append(f"{where} (sequence {sequence} is not in the campaign)")
                continue
            direction = DIRECTIONS[m.group("direction").lower()]
            entries.append(_Entry(where, sequence, direction, int(m.group("trial")), data))
    if bad:
        raise ImportRefused(
            f"{len(bad)} file(s) whose name does not match the pattern {pattern!r} (nothing imported):\n  "
            + "\n  ".join(bad[:20])
            + (f"\n  ... and {len(bad) - 20} more" if len(bad) > 20 else "")
        )
    return entries, skipped


def _where(source: Path, name: str) -> str:
    """How a user finds a member: the folder's file, the archive and its member, or the file itself."""
    if source.is_dir():
        return str(source / name)
    return str(source) if source.name == name else f"{source}:{name}"


def _trajectory(entry: _Entry, fmt: str, frames: np.ndarray) -> Trajectory | None:
    """The entry's poses (None for an empty file); a file that cannot be read is an error naming it."""
    if not entry.data.strip():
        return None
    with tempfile.NamedTemporaryFile(suffix=".txt") as f:
        f.write(entry.data)
        f.flush()
        try:
            if fmt == "kitti":
                traj = read_kitti(f.name, frames)
            elif fmt == "euroc":
                traj = read_euroc_csv(f.name)
            else:
                traj = read_tum(f.name)
        except TrajectoryFormatError as exc:
            raise ImportRefused(f"{entry.source}: {str(exc).split(': ', 1)[-1]}") from None
    return traj


def import_trajectories(
    results: Path, sources: list[Path], label: str, pattern: str | None = None, fmt: str = "tum"
) -> ImportReport:
    """Import the sources' trajectories into the campaign at `results` as runs of `label` (one transaction)."""
    results = Path(results)
    spec = _campaign_spec(results)
    if why := path_part_problem(label):
        raise ImportRefused(f"--as {label!r}: {why}")
    if label in {m.run_label for m in spec.methods}:
        raise ImportRefused(
            f"--as {label!r}: a method of the campaign has this label; choose another (e.g. study:{label})"
        )
    datasets = {seq: ds for ds in spec.datasets for seq in ds.sequences}
    entries, skipped = read_entries(sources, pattern or STUDY_PATTERN, set(datasets))
    report = ImportReport(skipped=skipped)
    settings = "imported-" + hashlib.sha256(label.encode()).hexdigest()[:8]
    ledger = Ledger(results / "ledger.sqlite")
    staged: list[tuple[Path, Path]] = []
    try:
        prepared = []
        sequences: dict[str, tuple] = {}
        for e in entries:  # read and check everything before anything is written
            ds = datasets[e.sequence]
            if e.sequence not in sequences:
                seq = open_sequence(ds.path / e.sequence, ds.layout)
                gt = seq.groundtruth() if spec.evaluate else None
                sequences[e.sequence] = (seq, gt, sequence_identity(seq.root))
            seq, gt, data = sequences[e.sequence]
            traj = _trajectory(e, fmt, seq.timestamps)
            if traj is not None and len(traj) and (why := foreign_timestamps_of(traj, seq.timestamps)):
                raise ImportRefused(f"{e.source}: not a trajectory of {e.sequence} ({why}); nothing imported")
            key = RunKey(label, e.sequence, e.direction, e.trial, settings, data)
            prepared.append((e, ds, seq, gt, traj, key))
        rows = []
        for e, ds, seq, gt, traj, key in prepared:
            row = ledger.get(key.id)
            if row is not None and row["state"] in ("done", "failed"):
                earlier = _recorded_sha(Path(row["run_dir"] or "")) if row["run_dir"] else None
                (report.unchanged if earlier == e.sha256 else report.kept).append(e.source)
                continue
            record = _record(key, e, ds, seq, gt, traj)
            paths = RunPaths(results, key)
            stage = paths.staging(0)
            shutil.rmtree(stage, ignore_errors=True)
            stage.mkdir(parents=True)
            staged.append((stage, paths.final))
            if traj is not None and len(traj):
                write_tum(RunPaths.trajectory(stage), traj)
            RunPaths.run_json(stage).write_text(jsonio.dumps(record, indent=1))
            rows.append(record | {"run_dir": str(paths.final)})
            report.imported.append(e.source)
        for _, final in staged:
            if final.exists():
                raise ImportRefused(f"{final}: a run folder exists that the ledger does not know; nothing imported")
        ledger.insert_finished(rows)  # one transaction
        for stage, final in staged:
            os.rename(stage, final)
        staged.clear()
    finally:
        for stage, _ in staged:
            shutil.rmtree(stage, ignore_errors=True)
        ledger.close()
    return report


def _campaign_spec(results: Path) -> CampaignSpec:
    check_campaign_folder(results)
    return load_spec(results / "spec.resolved.yaml")


def check_campaign_folder(results: Path) -> None:
    """A campaign's results folder (its ledger and resolved spec), or ImportRefused saying what to do."""
    if not (results / "ledger.sqlite").is_file() or not (results / "spec.resolved.yaml").is_file():
        raise ImportRefused(
            f"{results}: not a campaign's results folder (no ledger.sqlite and spec.resolved.yaml); run "
            "`slamrun campaign SPEC` once (`--dry-run` writes nothing), then import into its results folder"
        )


def _recorded_sha(run_dir: Path) -> str | None:
    try:
        return json.loads((run_dir / "run.json").read_text())["imported"]["sha256"]
    except (OSError, ValueError, KeyError, TypeError):
        return None


def _record(key: RunKey, e: _Entry, ds, seq, gt, traj: Trajectory | None) -> dict:
    """The run.json of an imported run: a result of the method as published (done, or no_output when the file
    has no finite pose), its metrics by the campaign's own evaluation, no resources."""
    values: dict = {"failure": None, "message": None}
    if traj is None or not len(traj):
        values.update(failure="no_output", message="the published file holds no finite pose")
    else:
        values.update(n_poses=len(traj), coverage=metrics.coverage(traj, seq.timestamps))
        if traj.report.n_nonfinite_dropped:
            values["message"] = f"{traj.report.n_nonfinite_dropped} NaN or infinite row(s) of the file dropped"
        if gt is not None:
            figures, detail = evaluate(gt, traj, tuple(ds.metrics), ds.alignment)
            values.update(figures)
            if detail and not values["message"]:
                values["message"] = detail
    return {
        "key": key.id,
        "label": key.label,
        "method": IMPORTED,
        "dataset": ds.name,
        "sequence": key.sequence,
        "data": key.data,
        "direction": key.direction.value,
        "trial": key.trial,
        "settings": key.settings,
        "state": "failed" if values["failure"] else "done",
        "attempts": 0,
        "ended_at": time.time(),
        "sequence_dir": str(seq.root),
        "imported": {"source": e.source, "sha256": e.sha256},
        "trajectory_report": traj.report.__dict__ if traj is not None else None,
        **values,
    }


def reimport_lost(ledger: Ledger, results: Path) -> int:
    """Imported runs whose run folder is complete but whose ledger row is gone (a lost or reset ledger) are
    recorded again from their run.json; returns how many."""
    rows = []
    for path in sorted((results / "runs").glob("*@imported-*/*/*/*/run.json")):
        try:
            rec = json.loads(path.read_text())
        except (OSError, ValueError):
            continue
        if isinstance(rec, dict) and rec.get("method") == IMPORTED and ledger.get(rec.get("key", "")) is None:
            rows.append(rec | {"run_dir": str(path.parent)})
    if rows:
        ledger.insert_finished(rows)
    return len(rows)
