"""Verify method images the way a user would: `slamrun images --verify` / `make verify-images`.

Per method: build the image when it is missing, run a short campaign with `backend: docker` on synthetic
sequences (two scenes, forward and backward, two trials), and report one row: built, build time, image
size, runs ok, e_align relative to the scene's extent (median and worst), the segment alignment errors in the
order the method met them (a start-up transient shows as a first segment far worse than the last, whatever the
direction), the settled error, fps and RAM. A method passes when every run ended done and evaluated and the
median settled error stays under its bound: the RMSE of a Sim(3) fit of the poses after the segment the method
processed first (the first 20 % of its frames), over the scene's extent. The verification proves the image and
adapter right (timestamps, direction, calibration, frame conventions: wrong ones give large errors everywhere),
so a method's own start-up transient, which the study measures as a result (LSD-SLAM's random initial depth), is
left out of the verdict and shown in the e_align and segment columns. An image built with an untrained stand-in
network (`--standin-model`) is judged on its plumbing alone, its accuracy is not.
"""

from __future__ import annotations

import json
import re
import statistics
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import yaml

import slamrun.methods
from slamrun.core import jsonio, metrics
from slamrun.core.trajectory import Trajectory, read_tum
from slamrun.engine.paths import RunPaths
from slamrun.errors import MetricError, SlamRunError
from slamrun.images.build import BuildOptions, build, buildable, last_record
from slamrun.methods.base import Method
from slamrun.methods.declare import VerifyScope, declared
from slamrun.results.catalogue import E_ALIGN
from slamrun.results.files import CampaignFiles

DEFAULT_RESULTS = Path(".cache") / "verify"  # under the current directory: where the user works
SEQUENCES = ("room_a", "room_b")
FRAMES = 300
TRIALS = 2
DEFAULT_BOUND = Method.verify_bound  # e_align / scene extent a verified run must stay under (median over its runs)


def scope_of(name: str) -> VerifyScope | None:
    """What method `name`'s verification runs where its folder declares less than the default (verify_scope)."""
    cls = slamrun.methods.REGISTRY.get(name)
    return declared(cls, "verify_scope") if cls else None


def bound_of(name: str) -> float:
    """The bound method `name` declares (verify_bound in its folder's declaration), else the default."""
    cls = slamrun.methods.REGISTRY.get(name)
    return declared(cls, "verify_bound", DEFAULT_BOUND) if cls else DEFAULT_BOUND


@dataclass
class VerifyRow:
    method: str
    built: bool
    build_min: float | None = None
    size_mb: float | None = None
    runs_ok: int = 0
    runs: int = 0
    e_align_rel_median: float | None = None
    e_align_rel_max: float | None = None
    seg_first_rel: float | None = None  # median segment RMSE / extent, the segment the method processed first
    seg_last_rel: float | None = None  # ... and last (forward: start, end; backward: end, start)
    settled_rel_median: float | None = None  # Sim(3) RMSE after the first-processed 20 % of frames / extent
    settled_rel_max: float | None = None
    scope: str = ""  # what ran, when not the default (the method's verify_scope)
    bound: float = DEFAULT_BOUND
    fps: float | None = None
    ram_mb: float | None = None
    vocabulary: str | None = None
    note: str = ""
    plumbing_only: bool = False  # an untrained stand-in network: accuracy is not judged
    backend: str = "docker"  # what ran it: images are verified through docker, a spec's methods through its backend

    @property
    def passed(self) -> bool:
        runs_ok = self.built and self.runs > 0 and self.runs_ok == self.runs
        if self.plumbing_only:
            return runs_ok
        return runs_ok and self.settled_rel_median is not None and self.settled_rel_median < self.bound


def holds_standin_network(labels: dict[str, str]) -> bool:
    """Whether an image's labels say it holds an untrained stand-in network (`slamrun images --standin-model`)."""
    try:
        weights = json.loads(labels.get("slamrun.weights") or "{}")
    except ValueError:
        return False
    return any("stand-in" in str(v) for v in weights.values())


def processed_segments(runs: list[dict], extents: dict[str, float]) -> tuple[float | None, float | None]:
    """Medians of the segment alignment RMSE over the scene's extent, for the segment each run processed first
    and the one it processed last (a backward run meets the end segment first)."""
    first, last = [], []
    for r in runs:
        seg = (r["e_start"], r["e_end"]) if r["direction"] == "forward" else (r["e_end"], r["e_start"])
        if None not in seg:
            first.append(seg[0] / extents[r["sequence"]])
            last.append(seg[1] / extents[r["sequence"]])
    if not first:
        return None, None
    return statistics.median(first), statistics.median(last)


def settled_error(trajectory: Path, sequence: Path, direction: str, fraction: float = 0.2) -> float | None:
    """The RMSE of a Sim(3) fit of a run's poses after the segment it processed first (the first `fraction` of the
    frames in its processing order: a backward run starts at the end) to the sequence's full ground truth; None
    when fewer than three poses remain."""
    frames = np.loadtxt(sequence / "times.txt", ndmin=2)[:, 1]
    n_seg = max(int(np.floor(fraction * len(frames))), 3)
    est = read_tum(trajectory)
    gt = read_tum(sequence / "groundtruth_full.txt")
    if direction == "forward":
        keep = est.timestamps > frames[n_seg - 1] + 1e-4
    else:
        keep = est.timestamps < frames[len(frames) - n_seg] - 1e-4
    if keep.sum() < 3:
        return None
    after = Trajectory(est.timestamps[keep], est.positions[keep], est.quaternions[keep])
    try:
        return metrics.ate(gt, after, "sim3", 1e-3).translation.rmse
    except MetricError:
        return None


MAX_GAP = 0.1  # a run is ok when no stretch of more than this share of its sequence's frames went without a pose


def pose_gap(trajectory: Path, sequence: Path) -> int:
    """The longest stretch of the sequence's frames (times.txt) without a pose of the run: a few frames for a method
    that writes keyframes only, most of the loop for a run lost early that relocalised at its end."""
    frames = np.loadtxt(sequence / "times.txt", ndmin=2)[:, 1]
    try:
        poses = read_tum(trajectory).timestamps
    except (OSError, ValueError, SlamRunError):
        return len(frames)
    has = np.zeros(len(frames), bool)
    i = np.clip(np.searchsorted(frames, poses), 0, len(frames) - 1)
    for j in (i, np.maximum(i - 1, 0)):
        has[j[np.abs(frames[j] - poses) <= 1e-3]] = True
    edges = np.flatnonzero(np.diff(np.concatenate(([1], has.astype(int), [1]))))  # starts and ends of the stretches
    return int(max((b - a for a, b in zip(edges[::2], edges[1::2], strict=True)), default=0))


def scene_extent(sequence: Path) -> float:
    """Diagonal of the bounding box of the camera path (the full ground truth of a synthetic sequence, else
    the rows of groundtruthSync.txt that carry numbers)."""
    full = sequence / "groundtruth_full.txt"
    gt = np.loadtxt(full if full.exists() else sequence / "groundtruthSync.txt")
    pos = gt[:, 1:4][np.isfinite(gt[:, 1:4]).all(axis=1)]
    if len(pos) < 2:
        raise SlamRunError(f"{sequence}: no ground-truth positions to measure the scene by")
    return float(np.linalg.norm(pos.max(axis=0) - pos.min(axis=0)))


def verify(
    names: list[str] | None,
    opts: BuildOptions,
    results: Path | None = None,
    log: Callable[[str], None] = print,
    trials: int = TRIALS,
    frames: int = FRAMES,
) -> list[VerifyRow]:
    from slamrun.backends.docker import DockerBackend

    results = Path(results or DEFAULT_RESULTS).resolve()
    names = names or [n for n in buildable() if slamrun.methods.REGISTRY[n].verified]
    client = DockerBackend().client.api
    rows = []
    for name in names:
        row = VerifyRow(name, built=False, bound=bound_of(name))
        rows.append(row)
        try:
            build([name], log=log, opts=opts, only_missing=True)
        except SlamRunError as exc:
            row.note = f"build failed: {str(exc).splitlines()[0]}"
            log(f"verify {name}: {row.note}")
            continue
        tag = buildable()[name][0]
        info = client.inspect_image(tag)
        row.built = True
        row.size_mb = round(info["Size"] / 2**20, 1)
        labels = (info.get("Config") or {}).get("Labels") or {}
        row.vocabulary = labels.get("slamrun.vocabulary")
        row.plumbing_only = holds_standin_network(labels)
        record = last_record(name, opts.log_dir)
        if record is not None and record.tag == tag:
            row.build_min = round(record.seconds / 60, 1)
        scope = scope_of(name)
        if scope is not None:
            row.scope = str(scope)
            _campaign(
                name,
                row,
                results,
                scope.trials,
                scope.frames,
                log,
                sequences=scope.sequences,
                timeout_s=scope.timeout_s,
            )
        else:
            _campaign(name, row, results, trials, frames, log)
    return _write_tables(results, rows)


def verify_spec(
    spec_path: Path,
    labels: list[str] | None = None,
    results: Path | None = None,
    log: Callable[[str], None] = print,
    trials: int = TRIALS,
    frames: int = FRAMES,
) -> list[VerifyRow]:
    """The same verification for the methods of a spec (built-in, plug-in or external, with their parameters and
    the spec's backend): a campaign on the synthetic rooms per method, one row each. No image is built here."""
    from slamrun.engine.spec_file import load_spec

    spec = load_spec(spec_path)
    results = Path(results or DEFAULT_RESULTS).resolve()
    chosen = [m for m in spec.methods if not labels or m.run_label in labels]
    unknown = sorted(set(labels or ()) - {m.run_label for m in spec.methods})
    if unknown:
        raise SlamRunError(
            f"{spec_path}: no method labelled {', '.join(unknown)} (labels: "
            f"{', '.join(m.run_label for m in spec.methods)})"
        )
    rows = []
    for m in chosen:
        row = VerifyRow(m.run_label, built=True, bound=bound_of(m.name), backend=spec.backend)
        rows.append(row)
        method = {"name": m.name, "label": m.run_label, "params": m.params}
        _campaign(m.run_label, row, results, trials, frames, log, method=method, backend=spec.backend)
    return _write_tables(results, rows)


def _write_tables(results: Path, rows: list[VerifyRow]) -> list[VerifyRow]:
    results.mkdir(parents=True, exist_ok=True)
    table = merged(results / "verify.json", rows)  # the rows of methods verified earlier stay
    (results / "verify.json").write_text(jsonio.dumps([asdict(r) | {"passed": r.passed} for r in table], indent=1))
    (results / "verify.md").write_text(markdown_table(table))
    return rows


def merged(path: Path, rows: list[VerifyRow]) -> list[VerifyRow]:
    """Earlier rows from `path`, with the methods of `rows` replaced, in the registry's order."""
    table: dict[str, VerifyRow] = {}
    try:
        for d in json.loads(path.read_text()):
            d.pop("passed", None)
            table[d["method"]] = VerifyRow(**d)
    except (OSError, ValueError, TypeError, KeyError):
        pass
    table.update({r.method: r for r in rows})
    order = list(buildable())
    return sorted(table.values(), key=lambda r: order.index(r.method) if r.method in order else len(order))


def _campaign(
    name: str,
    row: VerifyRow,
    results: Path,
    trials: int,
    frames: int,
    log,
    method: dict | None = None,
    backend: str = "docker",
    sequences: tuple[str, ...] = SEQUENCES,
    timeout_s: float = 900.0,
) -> None:
    from slamrun.engine.campaign import run_campaign
    from slamrun.engine.ledger import Ledger
    from slamrun.engine.spec_file import load_spec

    data = results / "data" if frames == FRAMES else results / f"data-{frames}"  # the rooms at that length
    spec = {
        "name": "verify-" + re.sub(r"[^A-Za-z0-9_.-]", "-", name),
        "results": str(results / name),
        "cache": str(results / "views"),
        "datasets": [
            {
                "name": "synth",
                "path": str(data),
                "sequences": list(sequences),
                "synthetic": {"frames": frames, "seed": 0, "size": "640x480", "scene": "indoor"},
            }
        ],
        "methods": [method or {"name": name}],
        "directions": ["forward", "backward"],
        "trials": trials,
        "lanes": 1,
        "timeout_s": timeout_s,
        "backend": backend,
        "report": False,
    }
    results.mkdir(parents=True, exist_ok=True)
    path = results / f"{name}.yaml"
    path.write_text(yaml.safe_dump(spec, sort_keys=False))
    run_campaign(load_spec(path), log=log)
    extents = {seq: scene_extent(data / seq) for seq in sequences}
    ledger = Ledger(CampaignFiles(results / name).ledger)
    try:
        done = [r for r in ledger.rows() if r["active"]]
    finally:
        ledger.close()
    frames = {seq: len(np.loadtxt(data / seq / "times.txt", ndmin=2)) for seq in sequences}
    for r in done:  # the longest stretch of frames without a pose (a done run's)
        r["gap"] = pose_gap(RunPaths.trajectory(Path(r["run_dir"])), data / r["sequence"]) if r["run_dir"] else None
        r["frames"] = frames[r["sequence"]]
    ok = [r for r in done if run_ok(r)]
    row.runs, row.runs_ok = len(done), len(ok)
    rel = [r[E_ALIGN] / extents[r["sequence"]] for r in ok]
    if rel:
        row.e_align_rel_median = statistics.median(rel)
        row.e_align_rel_max = max(rel)
    row.seg_first_rel, row.seg_last_rel = processed_segments(ok, extents)
    settled = [
        e / extents[r["sequence"]]
        for r in ok
        if (e := settled_error(RunPaths.trajectory(Path(r["run_dir"])), data / r["sequence"], r["direction"]))
        is not None
    ]
    if settled:
        row.settled_rel_median, row.settled_rel_max = statistics.median(settled), max(settled)
    fps = [r["fps"] for r in ok if r["fps"]]
    ram = [r["ram_peak_mb"] for r in ok if r["ram_peak_mb"]]
    row.fps = round(statistics.median(fps), 1) if fps else None
    row.ram_mb = round(statistics.median(ram)) if ram else None
    failed = [f"{r['sequence']}/{r['direction']}/{r['trial']}: {_why_not_ok(r)}" for r in done if r not in ok]
    if failed:
        row.note = "not ok: " + "; ".join(failed[:4]) + (f" (+{len(failed) - 4})" if len(failed) > 4 else "")


def run_ok(row) -> bool:
    """A verification run that counts: done and evaluated, and no stretch of over MAX_GAP of its sequence's frames
    without a pose (a run lost early that relocalised only at the loop's end is not ok, whatever its e_align; a method
    that writes its keyframes only is)."""
    done = row["status"] == "done" and row[E_ALIGN] is not None
    return done and (row.get("gap") or 0) <= MAX_GAP * (row.get("frames") or 0)


def _why_not_ok(row) -> str:
    """A run's failure kind, why a run that ended done has no e_align, or its low coverage."""
    if row["failure"]:
        return row["failure"]
    if row["status"] == "done" and row.get(E_ALIGN) is not None and not run_ok(row):
        return f"{row['gap']} of {row['frames']} frames in a row without a pose"
    if row["status"] == "done":
        return f"not evaluated ({row['eval_status'] or 'no metrics'})"
    return row["status"]


def _fmt(v, spec: str = "", none: str = "-") -> str:
    return none if v is None else format(v, spec)


PLUMBING = "plumbing only (stand-in network)"
# (markdown heading, terminal heading) of every column but the verdict
COLUMNS = (
    ("method", "method"),
    ("built", "built"),
    ("build (min)", "build min"),
    ("image (MB)", "MB"),
    ("runs ok", "runs ok"),
    ("e_align / extent, median (max)", "e_align/extent med (max)"),
    ("segment RMSE / extent, first / last processed", "segments first/last"),
    ("settled / extent, median (max)", "settled/extent med (max)"),
    ("bound", "bound"),
    ("fps", "fps"),
    ("RAM (MB)", "RAM MB"),
)


def _cells(r: VerifyRow) -> list[str]:
    """A row's cells, in COLUMNS' order."""
    e = "-" if r.e_align_rel_median is None else f"{r.e_align_rel_median:.4f} ({r.e_align_rel_max:.4f})"
    segments = "-" if r.seg_first_rel is None else f"{r.seg_first_rel:.5f} / {r.seg_last_rel:.5f}"
    settled = "-" if r.settled_rel_median is None else f"{r.settled_rel_median:.4f} ({r.settled_rel_max:.4f})"
    bound = PLUMBING if r.plumbing_only else f"{r.bound:.2f}"
    return [
        r.method,
        "yes" if r.built else "no",
        _fmt(r.build_min),
        _fmt(r.size_mb, ".0f"),
        f"{r.runs_ok}/{r.runs}" + (f" ({r.scope})" if r.scope else ""),
        e,
        segments,
        settled,
        bound,
        _fmt(r.fps),
        _fmt(r.ram_mb),
    ]


def markdown_table(rows: list[VerifyRow]) -> str:
    head = "| " + " | ".join(md for md, _ in COLUMNS) + " | verified |\n" + "|---" * (len(COLUMNS) + 1) + "|\n"
    lines = []
    for r in rows:
        verdict = "yes" if r.passed else f"no: {r.note}" if r.note else "no"
        lines.append("| " + " | ".join([*_cells(r), verdict]) + " |")
    return head + "\n".join(lines) + "\n"


def print_table(rows: list[VerifyRow], console) -> None:
    from rich.table import Table

    backends = ", ".join(sorted({r.backend for r in rows})) or "docker"
    table = Table(title=f"methods verified on synthetic sequences (backend: {backends})")
    for _, col in COLUMNS:
        table.add_column(col)
    table.add_column("verified")
    for r in rows:
        table.add_row(*_cells(r), "yes" if r.passed else f"no {r.note}".strip())
    console.print(table)
