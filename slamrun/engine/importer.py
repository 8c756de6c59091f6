"""Import published trajectories into a campaign's ledger as runs of a method label (e.g. `study:dso`).

Sources are folders, zip files, or split zip archives (`X.zip.001`, `X.zip.002`, ... joined in order), as the
study published its database (`<code>_<fw|bw>/sequence_SS_R.txt`). Each file's name gives its sequence, direction
and trial (the study's pattern, or `--pattern` with the named groups `sequence`, `direction` and `trial`). Each run
is recorded like a campaign's own: a run folder with trajectory.txt and run.json (the source file, its SHA-256,
`imported: true`, no resources), evaluated by the same code against the campaign's ground truth.

An import is one transaction: every file is listed, named and checked first, then read and evaluated into a
private folder of the results, and any problem (a corrupt archive part, a name that does not match, two files for
one run, a trajectory of another sequence, a file or an archive too large to be trajectories) stops it before
anything is written where the campaign looks. Re-importing the same files changes nothing; a run that exists is
never overwritten.

Bounded on hostile input: a file over MEMBER_MAX, or sources over TOTAL_MAX in all, are refused from the sizes the
archives and the file system state, before anything is inflated or read; the bytes read are counted against the
same bounds (a zip's stated sizes can lie). One file is in memory at a time.

Imported labels are `SOURCE:NAME` (e.g. `study:dso`); a spec's labels hold no ':' (the spec refuses one), so an
imported label never meets a method a campaign runs, now or after its spec changes.
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
from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

import numpy as np

from slamrun.backends.machine import source_commit
from slamrun.core import jsonio
from slamrun.core.archives import ZIP_ERRORS, files_of, read_member
from slamrun.core.formats import read_trajectory
from slamrun.core.inputs import read_bounded, regular_file_problem
from slamrun.core.trajectory import Trajectory, write_tum
from slamrun.datasets.layouts import open_sequence, sequence_identity
from slamrun.datasets.perturb import BASELINE
from slamrun.datasets.view import Direction
from slamrun.engine.execute import foreign_timestamps_of
from slamrun.engine.folders import path_part_problem
from slamrun.engine.ledger import Ledger, record_names
from slamrun.engine.paths import RunPaths
from slamrun.engine.plan import RunKey
from slamrun.engine.run_evaluation import evaluate_trajectory, run_frames, settle
from slamrun.engine.spec import CampaignSpec
from slamrun.engine.spec_file import load_spec
from slamrun.errors import SlamRunError, TrajectoryFormatError
from slamrun.results.files import CampaignFiles
from slamrun.results.vocabulary import IMPORTED

STUDY_PATTERN = r"(?:^|/)[a-z0-9-]+_(?P<direction>fw|bw)(?:__|/)sequence_(?P<sequence>\d+)_(?P<trial>\d+)\.txt$"
DIRECTIONS = {
    "fw": Direction.forward,
    "forward": Direction.forward,
    "bw": Direction.backward,
    "backward": Direction.backward,
}
DOCUMENTATION = ("readme", "license", "licence", "copying", "notice")
SPLIT_PART = re.compile(r"(.*)\.(\d{3})")
MEMBER_MAX = 64 * 2**20  # one trajectory file (the study's are under 1 MB: 64 MiB is some 600,000 poses)
TOTAL_MAX = 2 * 2**30  # everything one import reads


class ImportRefused(SlamRunError):
    """An import refused as a whole (nothing was written)."""


@dataclass
class ImportReport:
    imported: list[str] = field(default_factory=list)
    unchanged: list[str] = field(default_factory=list)  # the same file imported before
    kept: list[str] = field(default_factory=list)  # a run of that key exists from another file: not overwritten
    skipped: list[str] = field(default_factory=list)  # a sequence the campaign does not have


@dataclass(frozen=True)
class _Member:
    """A file of a source, listed: how a user finds it, the path the pattern reads, its stated size, and how to
    read it (bounded)."""

    where: str  # file, or archive:member
    name: str
    size: int
    read: Callable[[], bytes]


@dataclass(frozen=True)
class _Entry:
    member: _Member
    sequence: str
    direction: Direction
    trial: int

    @property
    def source(self) -> str:
        return self.member.where


def _is_documentation(name: str) -> bool:
    """Files a study's folder or repository holds beside its trajectories: hidden ones (`.git/`, `.gitattributes`,
    `__MACOSX/._x`), READMEs, licences, Markdown."""
    path = Path(name)
    if any(part.startswith(".") for part in path.parts):
        return True
    return path.stem.lower() in DOCUMENTATION or path.suffix.lower() in (".md", ".rst")


def _open_sources(sources: list[Path], stack: ExitStack) -> list[_Member]:
    """Every file of the sources, listed (archives opened, nothing inflated or read yet); the archives stay open
    until `stack` closes."""
    found: list[_Member] = []
    for source in sources:
        source = Path(source)
        found += _folder_members(source, stack) if source.is_dir() else _file_members(source, stack)
    return found


def _folder_members(folder: Path, stack: ExitStack) -> list[_Member]:
    """A folder's trajectory files, and the members of the zips and split zips in it (the study's repository as
    cloned: `<code>_<dir>.zip.001`, `.002`, ...); hidden folders (`.git`) and documentation left out."""
    found: list[_Member] = []
    for root, dirs, files in os.walk(folder):
        dirs[:] = sorted(d for d in dirs if not d.startswith("."))
        for name in sorted(files):
            path = Path(root) / name
            rel = path.relative_to(folder).as_posix()
            if _is_documentation(rel):
                continue
            part = SPLIT_PART.fullmatch(name)
            part = part if part is not None and part.group(1).lower().endswith(".zip") else None
            if part is not None and part.group(2) != "001":
                if not path.with_name(f"{part.group(1)}.001").is_file():
                    raise ImportRefused(
                        f"{path}: no {part.group(1)}.001 beside it (the first part of the split archive)"
                    )
                continue  # joined from its first part
            if part is not None or name.lower().endswith(".zip"):
                found += _file_members(path, stack)
            else:
                found.append(_plain_file(path, str(path), rel))
    return found


def _plain_file(path: Path, where: str, name: str) -> _Member:
    if why := regular_file_problem(path, "a trajectory file"):
        raise ImportRefused(f"{why}; nothing imported")
    read = partial(read_bounded, path, MEMBER_MAX, "a trajectory file", ImportRefused)
    return _Member(where, name, path.stat().st_size, read)


def _file_members(source: Path, stack: ExitStack) -> list[_Member]:
    """The members of a zip or split zip, or a single trajectory file."""
    parts = split_parts(source)
    if parts is None:
        if not source.exists():
            raise ImportRefused(f"{source}: not found; expected a folder, a zip or the first part of a split zip")
        if why := regular_file_problem(source, "a folder, a zip or a trajectory file"):
            raise ImportRefused(why)
        if not zipfile.is_zipfile(source):
            return [_plain_file(source, str(source), source.name)]
        parts = [source]
    return _archive_members(parts, stack)


def _archive_members(parts: list[Path], stack: ExitStack) -> list[_Member]:
    """The files of a zip, or of a split zip's parts joined in order; listed from the archive's directory."""
    first = parts[0]
    path = first
    if len(parts) > 1:
        path = Path(stack.enter_context(tempfile.TemporaryDirectory())) / "joined.zip"
        with open(path, "wb") as out:
            for p in parts:
                with open(p, "rb") as f:
                    shutil.copyfileobj(f, out)
    try:
        zf = stack.enter_context(zipfile.ZipFile(path))
    except ZIP_ERRORS as exc:
        names = ", ".join(p.name for p in parts)
        raise ImportRefused(f"{first}: not a readable zip ({exc}); its parts: {names}") from None
    return [
        _Member(
            f"{first}:{info.filename}",
            info.filename,
            info.file_size,
            partial(read_member, zf, info, f"{first}:{info.filename}", MEMBER_MAX, "a trajectory file", ImportRefused),
        )
        for info in files_of(zf)
    ]


def split_parts(source: Path) -> list[Path] | None:
    """The parts of a split archive, in order, from its first (`name.zip.001`, `.002`, ...); None otherwise."""
    m = SPLIT_PART.fullmatch(source.name)
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


def _match(members: list[_Member], pattern: str, known: set[str]) -> tuple[list[_Entry], list[str]]:
    """Each member with its sequence, direction and trial; names that do not match are errors (all named at
    once), members of sequences not in `known` are skipped (named)."""
    rx = re.compile(pattern)
    for group in ("sequence", "direction", "trial"):
        if group not in rx.groupindex:
            raise ImportRefused(f"--pattern {pattern!r}: needs the named group (?P<{group}>...)")
    entries, bad, skipped = [], [], []
    for member in members:
        if _is_documentation(member.name):
            continue
        m = rx.search(member.name)
        if m is None or m.group("direction").lower() not in DIRECTIONS or not m.group("trial").isdigit():
            bad.append(member.where)
            continue
        sequence = _sequence_name(m.group("sequence"), known)
        if sequence not in known:
            skipped.append(f"{member.where} (sequence {sequence} is not in the campaign)")
            continue
        entries.append(_Entry(member, sequence, DIRECTIONS[m.group("direction").lower()], int(m.group("trial"))))
    if bad:
        raise ImportRefused(
            f"{len(bad)} file(s) whose name does not match the pattern {pattern!r} (nothing imported):\n  "
            + "\n  ".join(bad[:20])
            + (f"\n  ... and {len(bad) - 20} more" if len(bad) > 20 else "")
        )
    return entries, skipped


def _check_sizes(entries: list[_Entry]) -> None:
    """Before anything is inflated or read: no file over MEMBER_MAX, and at most TOTAL_MAX in all (as stated by
    the archives and the file system; the bytes read are counted against the same bounds)."""
    for e in entries:
        if e.member.size > MEMBER_MAX:
            raise ImportRefused(
                f"{e.source}: {e.member.size:,} bytes unpacked; a trajectory file is at most {MEMBER_MAX:,} bytes "
                "(a zip bomb?); nothing imported"
            )
    total = sum(e.member.size for e in entries)
    if total > TOTAL_MAX:
        origins = sorted({e.source.rsplit(":", 1)[0] if ":" in e.source else e.source for e in entries})
        named = ", ".join(origins[:3]) + (f" and {len(origins) - 3} more" if len(origins) > 3 else "")
        raise ImportRefused(
            f"{named}: {total:,} bytes in all to unpack; one import reads at most {TOTAL_MAX:,} bytes (a zip bomb? "
            "or import the archives one at a time); nothing imported"
        )


def _check_one_file_per_run(entries: list[_Entry]) -> None:
    """Two files for one run (`sequence_01_7` and `sequence_1_7`, or one member twice in a zip) are an error
    naming both, before anything is read: which one holds the run's poses is not slamrun's to guess."""
    seen: dict[tuple, str] = {}
    clashes = []
    for e in entries:
        run = (e.sequence, e.direction, e.trial)
        if run in seen:
            twice = " (two members of that name)" if seen[run] == e.source else ""
            clashes.append(f"{e.sequence} {e.direction.value} trial {e.trial}: {seen[run]} and {e.source}{twice}")
        else:
            seen[run] = e.source
    if clashes:
        raise ImportRefused(
            f"{len(clashes)} run(s) with two files in this import (nothing imported; keep one file per run, or "
            "import them under different labels):\n  "
            + "\n  ".join(clashes[:20])
            + (f"\n  ... and {len(clashes) - 20} more" if len(clashes) > 20 else "")
        )


def _trajectory(source: str, data: bytes, fmt: str, frames: np.ndarray) -> Trajectory | None:
    """A file's poses (None for an empty file); a file that cannot be read is an error naming it."""
    if not data.strip():
        return None
    with tempfile.NamedTemporaryFile(suffix=".txt") as f:
        f.write(data)
        f.flush()
        try:
            traj = read_trajectory(f.name, fmt, frames)
        except TrajectoryFormatError as exc:
            raise ImportRefused(f"{source}: {str(exc).split(': ', 1)[-1]}") from None
    return traj


def label_problem(label: str, spec: CampaignSpec) -> str | None:
    """Why `label` cannot name imported runs, or None. An imported label is SOURCE:NAME; a spec's labels hold no
    ':' (spec.py refuses one), so imported runs never pool with a method's own, whatever the spec runs later."""
    if why := path_part_problem(label):
        return f"the label (a folder name in the results) {why}"
    source, _, name = label.partition(":")
    if not source or not name:
        return (
            "an imported label is SOURCE:NAME (e.g. study:dso, or study:reference_vo): the ':' keeps imported runs "
            "apart from the methods a spec runs, whose labels never hold one"
        )
    if label in {m.run_label for m in spec.methods}:
        return f"a method of the campaign has this label; choose another (e.g. study:{name})"
    return None


def import_trajectories(
    results: Path, sources: list[Path], label: str, pattern: str | None = None, fmt: str = "tum"
) -> ImportReport:
    """Import the sources' trajectories into the campaign at `results` as runs of `label` (one transaction)."""
    results = Path(results)
    spec = _campaign_spec(results)
    if why := label_problem(label, spec):
        raise ImportRefused(f"--as {label!r}: {why}")
    datasets = {seq: ds for ds in spec.datasets for seq in ds.sequences}
    with ExitStack() as stack:
        entries, skipped = _match(_open_sources(sources, stack), pattern or STUDY_PATTERN, set(datasets))
        _check_sizes(entries)
        _check_one_file_per_run(entries)
        report = ImportReport(skipped=skipped)
        ledger = Ledger(CampaignFiles(results).ledger)
        stack.callback(ledger.close)
        private = Path(tempfile.mkdtemp(prefix=".import-", dir=results))
        stack.callback(shutil.rmtree, private, True)
        staged = _stage(entries, label, fmt, spec, datasets, ledger, private, report)
        _commit(results, staged, ledger)
    return report


def _stage(
    entries: list[_Entry],
    label: str,
    fmt: str,
    spec: CampaignSpec,
    datasets: dict,
    ledger: Ledger,
    private: Path,
    report: ImportReport,
) -> list[tuple[Path, RunKey, dict]]:
    """Read, check and evaluate each file, one at a time, into a run folder under `private`: (that folder, the
    run's key, its run.json) for each run to import; unchanged and kept files go into `report`."""
    settings = "imported-" + hashlib.sha256(label.encode()).hexdigest()[:8]
    sequences: dict[str, tuple] = {}
    staged, read = [], 0
    for i, e in enumerate(entries):
        ds = datasets[e.sequence]
        if e.sequence not in sequences:
            seq = open_sequence(ds.path / e.sequence, ds.layout)
            gt = seq.groundtruth() if spec.evaluate else None
            sequences[e.sequence] = (seq, gt, sequence_identity(seq.root))
        seq, gt, identity = sequences[e.sequence]
        data = e.member.read()
        read += len(data)
        if len(data) > e.member.size or read > TOTAL_MAX:  # more than the file system or the archive stated
            raise ImportRefused(f"{e.source}: more bytes than stated ({len(data):,}); nothing imported")
        sha = hashlib.sha256(data).hexdigest()
        traj = _trajectory(e.source, data, fmt, seq.timestamps)
        del data
        if traj is not None and len(traj) and (why := foreign_timestamps_of(traj, seq.timestamps)):
            raise ImportRefused(f"{e.source}: not a trajectory of {e.sequence} ({why}); nothing imported")
        key = RunKey(label, e.sequence, e.direction, e.trial, settings, identity)
        row = ledger.get(key.id)
        if row is not None and row["status"] in ("done", "failed"):
            earlier = _recorded_sha(Path(row["run_dir"] or "")) if row["run_dir"] else None
            (report.unchanged if earlier == sha else report.kept).append(e.source)
            continue
        record = _record(key, e.source, sha, ds, seq, gt, traj)
        stage = private / str(i)
        stage.mkdir()
        if traj is not None and len(traj):
            write_tum(RunPaths.trajectory(stage), traj)
        RunPaths.run_json(stage).write_text(jsonio.dumps(record, indent=1))
        staged.append((stage, key, record))
        report.imported.append(e.source)
    return staged


def _commit(results: Path, staged: list[tuple[Path, RunKey, dict]], ledger: Ledger) -> None:
    """Move the staged run folders into place, then record them in the ledger in one transaction (a run folder
    without its row, after a crash, is recorded at the next start: `reimport_lost`); undone on any failure."""
    finals = [RunPaths(results, key).final for _, key, _ in staged]
    for final in finals:
        if final.exists():
            raise ImportRefused(f"{final}: a run folder exists that the ledger does not know; nothing imported")
    placed: list[Path] = []
    try:
        for (stage, _, _), final in zip(staged, finals, strict=True):
            final.parent.mkdir(parents=True, exist_ok=True)
            os.rename(stage, final)
            placed.append(final)
        rows = [record | {"run_dir": str(final)} for (_, _, record), final in zip(staged, finals, strict=True)]
        ledger.insert_finished(rows)
    except BaseException:
        for final in placed:
            shutil.rmtree(final, ignore_errors=True)
        raise


def _campaign_spec(results: Path) -> CampaignSpec:
    check_campaign_folder(results)
    return load_spec(CampaignFiles(results).spec, check_gpu=False)  # importing runs needs no GPU here


def check_campaign_folder(results: Path) -> None:
    """A campaign's results folder (its ledger and resolved spec), or ImportRefused saying what to do."""
    if not CampaignFiles(results).ledger.is_file() or not CampaignFiles(results).spec.is_file():
        raise ImportRefused(
            f"{results}: not a campaign's results folder (no ledger.sqlite and spec.resolved.yaml); run "
            "`slamrun campaign SPEC` once (`--dry-run` writes nothing), then import into its results folder"
        )


def _recorded_sha(run_dir: Path) -> str | None:
    try:
        return json.loads(RunPaths.run_json(run_dir).read_text())["imported"]["sha256"]
    except (OSError, ValueError, KeyError, TypeError):
        return None


def _record(key: RunKey, source: str, sha256: str, ds, seq, gt, traj: Trajectory | None) -> dict:
    """The run.json of an imported run: a result of the method as published (done, or no_output when the file
    has no finite pose), its metrics by the campaign's own evaluation, no resources."""
    values: dict = {"failure": None, "message": None, "method_failure": None, "eval_settings": ds.evaluation.text()}
    values["slamrun_commit"] = source_commit()  # the code that imported and evaluated it
    if traj is None or not len(traj):
        values.update(failure="no_output", message="the published file holds no finite pose")
    else:  # evaluated as a campaign's own run (coverage of every frame: a published file has no stride of ours)
        frames = run_frames(seq.timestamps, BASELINE, key.direction)
        figures, detail = evaluate_trajectory(traj, gt, frames, ds.evaluation)
        values.update(figures)
        dropped = traj.report.n_nonfinite_dropped
        note = f"{dropped} NaN or infinite row(s) of the file dropped" if dropped else None
        settle(values, None, note, detail, ds.evaluation)
    return {
        "key": key.id,
        "method": key.label,
        "method_name": IMPORTED,
        "dataset": ds.name,
        "sequence": key.sequence,
        "data": key.data,
        "direction": key.direction.value,
        "trial": key.trial,
        "settings": key.settings,
        "status": "failed" if values["failure"] else "done",
        "attempts": 0,
        "ended_at": time.time(),
        "sequence_dir": str(seq.root),
        "imported": {"source": source, "sha256": sha256},
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
        rec = record_names(rec) if isinstance(rec, dict) else rec
        if isinstance(rec, dict) and rec.get("method_name") == IMPORTED and ledger.get(rec.get("key", "")) is None:
            rows.append(rec | {"run_dir": str(path.parent)})
    if rows:
        ledger.insert_finished(rows)
    return len(rows)
