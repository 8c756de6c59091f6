"""What produced a campaign's results, for its report: the spec as run, slamrun's version and commit, each image's
labels (sources, vocabulary, weights), the backend, the host, the dates, the runs and their total time. Each item
is read from the results folder (spec.resolved.yaml, images.json, the ledger, the results table) or from the
running slamrun; an item that cannot be known says so instead of failing the report."""

from __future__ import annotations

import datetime
import json
import os
import platform
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from slamrun.backends.machine import cpu_model, source_commit
from slamrun.core.inputs import load_yaml_file, read_text_bounded
from slamrun.engine.session import measurement_conditions
from slamrun.engine.spec import RecordedSpec
from slamrun.errors import SlamRunError
from slamrun.results.catalogue import WALL_S
from slamrun.results.files import SPEC, CampaignFiles

IMAGES_FILE = "images.json"
MAX_BYTES = 4 << 20  # spec and images.json: a few kB in practice


@dataclass
class Provenance:
    campaign: str
    spec_text: str | None  # the spec as run (spec.resolved.yaml), None where the folder has none
    spec_note: str  # where it came from, or why it is missing
    version: str  # slamrun's
    commit: str  # slamrun's source tree, where it is a git checkout: the code writing the report
    backend: str
    images: dict[str, dict[str, str]]  # run label -> image label -> text
    images_note: str
    host: dict[str, str]  # the machine writing the report
    runs_host: str  # where the runs ran, as far as is known
    dates: dict[str, str]
    runs: dict[str, str]
    packages: dict[str, str] = field(default_factory=dict)  # run label -> the Python packages its runs ran on
    notes: list[str] = field(default_factory=list)
    measurement: str = ""  # under which measurement the resources were taken (parallel with N lanes, exclusive)
    contention_pct: float | None = None  # the spec's threshold of cpu_wait_pct for `contended` runs
    run_commits: str = ""  # the code that ran the runs: each commit and how many runs it made
    published: list[str] = field(default_factory=list)  # the spec's files of published figures (besides built-ins)


def provenance(results: Path, df: pd.DataFrame) -> Provenance:
    """The provenance of the results in folder `results` (its table `df`)."""
    results = Path(results)
    meta = _ledger_meta(results)
    recorded, spec_text, spec_note = _spec(results, meta.get("spec"))
    spec = RecordedSpec.read(recorded)
    images, images_note = _images(results)
    backend = spec.backend if spec else "not recorded"
    if spec and spec.distributed:
        backend += f", distributed ({_brief(spec.distributed)})"
    return Provenance(
        campaign=str(meta.get("campaign") or (spec and spec.name) or results.name),
        spec_text=spec_text,
        spec_note=spec_note,
        version=slamrun_version(),
        commit=source_commit(),
        backend=backend,
        images=images,
        images_note=images_note,
        host=host_description(),
        runs_host=_runs_host(meta.get("session"), spec, df),
        packages=_packages(df),
        dates=_dates(meta),
        runs=_runs(df, meta.get("session")),
        measurement=measurement_conditions(recorded),
        contention_pct=spec.contention_pct if spec else None,
        run_commits=run_commits(df),
        published=list(spec.published) if spec else [],
    )


def recorded_spec(results: Path) -> RecordedSpec | None:
    """The spec a results folder ran, as the report reads it (the ledger's record, else spec.resolved.yaml, bounded);
    None where neither can be read."""
    results = Path(results)
    recorded, _, _ = _spec(results, _ledger_meta(results).get("spec"))
    return RecordedSpec.read(recorded)


def run_commits(df: pd.DataFrame) -> str:
    """The slamrun commits the finished runs were made with, each with its count, and a warning where there are
    several (figures made by different code); runs recorded before commits were kept are counted apart."""
    if "status" in df.columns:
        df = df[df["status"].isin(["done", "failed"])]
    if df.empty:
        return "no finished run"
    commits = df["slamrun_commit"] if "slamrun_commit" in df.columns else pd.Series(None, index=df.index)
    named = [c if isinstance(c, str) and c else "not recorded (run before slamrun kept it)" for c in commits]
    counts = pd.Series(named, dtype=object).value_counts()
    text = "; ".join(f"{c}: {n} run(s)" for c, n in counts.items())
    known = [c for c in counts.index if not c.startswith("not recorded")]
    if len(counts) > 1:
        text = f"made by {len(counts)} versions of the code ({text}): their figures may differ by it"
    elif known and any("local changes" in c for c in known):
        text += " (a tree with changes not committed: the commit alone does not name the code)"
    return text


def _ledger_meta(results: Path) -> dict:
    """The ledger's campaign, spec and session records, and its runs' first start and last end; {} without one."""
    path = CampaignFiles(results).ledger
    if not path.is_file():
        return {}
    from slamrun.engine.ledger import Ledger

    try:
        ledger = Ledger(path, read_only=True)
    except (SlamRunError, OSError, ValueError):
        return {}
    try:
        out = {k: ledger.meta(k) for k in ("campaign", "spec", "session")}
        rows = ledger.rows(columns=("started_at", "ended_at"))
    except Exception:  # noqa: BLE001 - a ledger that cannot be read gives no dates, not a failed report
        return {}
    finally:
        ledger.close()
    starts = [r["started_at"] for r in rows if r["started_at"]]
    ends = [r["ended_at"] for r in rows if r["ended_at"]]
    out["first_start"] = min(starts) if starts else None
    out["last_end"] = max(ends) if ends else None
    return out


def _spec(results: Path, recorded: dict | None) -> tuple[dict | None, str | None, str]:
    """The spec as run: its values (the ledger's record, else the file's), its text and where the text is from."""
    path = CampaignFiles(results).spec
    if not (path.exists() or path.is_symlink()):
        return recorded, None, f"no {SPEC} in {results}"
    try:
        text = read_text_bounded(path, MAX_BYTES, "resolved spec")
    except SlamRunError as exc:
        return recorded, None, f"unreadable: {exc}"
    if recorded is None:
        try:
            recorded = load_yaml_file(path, "resolved spec")
        except SlamRunError as exc:
            return None, text, f"{SPEC} (not a readable spec: {exc})"
    return (recorded if isinstance(recorded, dict) else None), text, SPEC


def _images(results: Path) -> tuple[dict[str, dict[str, str]], str]:
    """images.json: per run label, the image's tag, id and slamrun.* labels, JSON-valued labels (sources, weights)
    spelt out; ({}, why) without one."""
    path = results / IMAGES_FILE
    if not (path.exists() or path.is_symlink()):
        return {}, "no image: the runs ran natively (no images.json)"
    try:
        raw = json.loads(read_text_bounded(path, MAX_BYTES, "image description"))
    except (SlamRunError, ValueError, RecursionError) as exc:  # RecursionError: nested past Python's limit
        return {}, f"{path}: unreadable ({str(exc)[:300]})"
    if not isinstance(raw, dict):
        return {}, f"{path}: expected an object of run labels"
    out = {}
    for label, labels in raw.items():
        if isinstance(labels, dict):
            out[str(label)] = {str(k): _spelt(v) for k, v in labels.items()}
        else:
            out[str(label)] = {"image": "not known to the backend"}
    return out, IMAGES_FILE


def _spelt(value) -> str:
    """A label's value as text: a JSON object held as a string (sources, weights) as `key: value` pairs."""
    if isinstance(value, str):
        try:
            decoded = json.loads(value)
        except ValueError:
            return value
        value = decoded if isinstance(decoded, dict) else value
    if isinstance(value, dict):
        return "; ".join(f"{k}: {v}" for k, v in value.items())
    return str(value)


def _brief(value) -> str:
    return json.dumps(value, sort_keys=True)[:200] if not isinstance(value, str) else value


def slamrun_version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("slamrun")
    except PackageNotFoundError:
        return "not installed as a package"


def host_description() -> dict[str, str]:
    """This machine: name, operating system, CPU model and cores, memory, GPUs (from the NVIDIA driver)."""
    import psutil

    return {
        "name": platform.node() or "unknown",
        "system": f"{platform.system()} {platform.release()} ({platform.machine()})",
        "CPU": f"{cpu_model()}, {os.cpu_count()} logical cores",
        "memory": f"{psutil.virtual_memory().total / 2**30:.1f} GiB",
        "GPU": _gpus(),
    }


def _gpus() -> str:
    """The GPUs this host's driver lists (NVML, else nvidia-smi -L), else none found."""
    from slamrun.backends.monitor import host_gpus

    return "; ".join(host_gpus()) or "none found"


def _runs_host(session: dict | None, spec: RecordedSpec | None, df: pd.DataFrame | None = None) -> str:
    """Where the runs ran: the hosts each run recorded (run.json has their CPU, GPUs and Slurm node), else this
    machine when the campaign's own process writes the report and the runs ran on it (backend local, docker or
    podman, not distributed); otherwise what is known."""
    if df is not None and "host" in df.columns and df["host"].notna().any():
        counts = df["host"].dropna().value_counts()
        missing = int(df["host"].isna().sum())
        text = ", ".join(f"{host} ({n} run{'s' if n != 1 else ''})" for host, n in counts.items())
        return text + (f"; {missing} run(s) without a record (imported, or not started)" if missing else "")
    local = spec is not None and not spec.distributed
    if session and session.get("pid") == os.getpid() and local:
        return "this machine (the campaign's own process wrote this report)"
    if spec is not None and spec.distributed:
        return "the distributed engine's workers (their hosts are not recorded)"
    return "not recorded in the results; this report was written later, on the machine below"


def _packages(df: pd.DataFrame) -> dict[str, str]:
    """Per method label, the package versions its native runs recorded (each set, where they differ)."""
    if "packages" not in df.columns or "method" not in df.columns:
        return {}
    out = {}
    for label, part in df.dropna(subset=["packages"]).groupby("method", sort=True):
        sets = part["packages"].value_counts()
        out[str(label)] = " | ".join(f"{s} ({n} runs)" if len(sets) > 1 else s for s, n in sets.items())
    return out


def _when(t) -> str:
    if t is None or not isinstance(t, int | float):
        return "not recorded"
    return datetime.datetime.fromtimestamp(t, datetime.UTC).strftime("%Y-%m-%d %H:%M:%S UTC")


def _dates(meta: dict) -> dict[str, str]:
    now = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M:%S UTC")
    return {
        "first run started": _when(meta.get("first_start")),
        "last run ended": _when(meta.get("last_end")),
        "report written": now,
    }


def _duration(seconds: float) -> str:
    seconds = float(seconds)
    if seconds < 120:
        return f"{seconds:.1f} s"
    if seconds < 7200:
        return f"{seconds / 60:.1f} min"
    return f"{seconds / 3600:.2f} h"


def _runs(df: pd.DataFrame, session: dict | None) -> dict[str, str]:
    """How many runs in which state, their summed time and the campaign's last session's span."""
    status = df["status"].fillna("unknown").value_counts() if "status" in df.columns else pd.Series({"done": len(df)})
    out = {"runs": f"{len(df)} (" + ", ".join(f"{k} {v}" for k, v in status.items()) + ")"}
    if WALL_S in df.columns and df[WALL_S].notna().any():
        out["total run time"] = f"{_duration(df[WALL_S].sum())} (the runs' wall-clock times summed)"
    if session and session.get("runs_from") and session.get("runs_to"):
        lanes = session.get("lanes")
        span = _duration(session["runs_to"] - session["runs_from"])
        out["last session"] = f"{span} from its first run's start to its last run's end, {lanes} lane(s)"
    return out
