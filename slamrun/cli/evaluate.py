"""slamrun evaluate: metrics of trajectory files against a ground truth (TUM-Mono's, ATE, RPE, KITTI's), on every
core. The ground truth is a sequence folder (evaluated exactly as a campaign evaluates its runs) or a file as it is.
Exit 0 when every file was evaluated, 1 when any could not be (said on stderr with how many)."""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from pathlib import Path

from slamrun.core import jsonio
from slamrun.core.formats import FORMATS, RECOGNISED
from slamrun.core.inputs import read_bounded
from slamrun.errors import SlamRunError
from slamrun.results.catalogue import METRIC_NAMES, RPE_UNITS
from slamrun.results.files import RUN_RECORD

GT_FORMATS = ("tum-mono", *FORMATS)  # TUM-Mono's groundtruthSync.txt, and the trajectory formats


def add_commands(sub) -> None:
    e = sub.add_parser(
        "evaluate",
        help="metrics of trajectory files against a ground truth",
        description="Metrics of trajectory files against a ground truth. --gt SEQUENCE_FOLDER (any layout slamrun "
        "reads) evaluates as a campaign does: the layout's ground truth in the camera's frame at the frames, its "
        "default metrics, the campaign's association and alignment; results.csv's figures for a run's "
        "trajectory.txt. Exit 0 when every file was evaluated, 1 when any could not be.",
    )
    e.add_argument(
        "--gt",
        type=Path,
        required=True,
        help="a sequence folder (the campaign's ground truth), or a ground-truth file as it is (groundtruthSync.txt, "
        "TUM, EuRoC/ASL csv, KITTI poses)",
    )
    e.add_argument(
        "--gt-format",
        choices=GT_FORMATS,
        help="a ground-truth file's format: tum-mono (groundtruthSync, NaN rows kept), tum, euroc (state csv, ns), "
        "kitti (poses, with --times); default: recognised from its first row, and a TUM file as TUM-Mono's by its "
        "name (groundtruthSync.txt) or its rows (poses at the start and the end, NaN rows between)",
    )
    e.add_argument(
        "--metric",
        action="append",
        choices=METRIC_NAMES,
        help="a metric (repeat for several); default: the dataset's (a folder's layout: tum-mono for TUM-Mono, ate "
        "and rpe, and kitti for KITTI); for a file its format's: tum-mono for TUM-Mono's groundtruthSync.txt, ate "
        "and rpe for any other TUM file and an EuRoC csv, and kitti too for KITTI poses",
    )
    e.add_argument("--align", help="sim3 (monocular, default), se3, none, first:N, se3:first:N")
    e.add_argument("--delta", type=_positive_float, help="RPE: the interval of a pose pair, in --delta-unit")
    e.add_argument(
        "--delta-unit",
        choices=RPE_UNITS,
        help="RPE: frames (the sequence's: with a folder or --times), s, m (along the ground truth), or evo's own "
        "evo-f / evo-m (evo_rpe --delta_unit f / m: steps of the estimate's poses); default: the dataset's, 1 s "
        "for every built-in layout (delta 1 when only the unit is given)",
    )
    e.add_argument(
        "--tolerance", type=_tolerance, help="association: largest time difference in s (default 0.02; a folder: 1 ms)"
    )
    e.add_argument(
        "--est-format",
        choices=[*FORMATS, RECOGNISED],
        default="tum",
        help="the estimates' format (auto: each file's first row tells: commas an EuRoC csv, 12 numbers KITTI poses, "
        "else TUM)",
    )
    e.add_argument(
        "--times",
        type=Path,
        help="the sequence's frame times (KITTI's times.txt) with a ground-truth file: the rows of KITTI poses, "
        "and the frames RPE in frames counts",
    )
    e.add_argument(
        "--any-sequence",
        action="store_true",
        help="evaluate a run's trajectory even where its run.json records other data than --gt's folder holds (its "
        "data digest; an older run.json without one: its sequence's name)",
    )
    e.add_argument("--json", action="store_true", help="one JSON object per line")
    e.add_argument("traj", type=Path, nargs="+", help="trajectory files")
    e.add_argument("--jobs", type=_jobs, help="worker processes (default: every core); output stays in input order")
    e.set_defaults(func=cmd_evaluate)


def _jobs(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise argparse.ArgumentTypeError(f"{_quoted(text)}: expected a whole number of processes, at least 1")
    return n


def _finite(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        v = math.nan
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"{_quoted(text)}: expected a finite number")
    return v


def _tolerance(text: str) -> float:
    v = _finite(text)
    if v < 0:
        raise argparse.ArgumentTypeError(f"{_quoted(text)}: expected seconds, 0 or more")
    return v


def _positive_float(text: str) -> float:
    v = _finite(text)
    if v <= 0:
        raise argparse.ArgumentTypeError(f"{_quoted(text)}: expected a number above 0")
    return v


def cmd_evaluate(args) -> int:
    from slamrun.core.batch_eval import evaluate_files, keep_freed_memory
    from slamrun.core.metrics import Alignment, RpeInterval
    from slamrun.datasets.groundtruth import open_groundtruth

    keep_freed_memory()
    Alignment.parse(args.align or "sim3")  # a bad --align or RPE interval is named before any file is read
    if args.delta is not None or args.delta_unit is not None:
        RpeInterval(args.delta or 1.0, args.delta_unit or "s")
    metrics = tuple(dict.fromkeys(args.metric)) if args.metric else None
    if args.gt.is_dir():
        _folder_form_only(args)
    elif args.est_format == "kitti" and args.times is None:
        raise SlamRunError("KITTI poses carry no timestamps: give the sequence's times.txt with --times")
    gt = open_groundtruth(args.gt, args.gt_format, metrics, args.times)
    for note in gt.notes:
        print(f"slamrun: note: {note}", file=sys.stderr)
    if gt.is_folder and not args.any_sequence:
        _same_sequence(args.gt, args.traj)
    opts = _options(args, gt, metrics or gt.default_metrics)
    failed = total = 0
    for d in evaluate_files(gt.trajectory, args.traj, args.jobs, opts):
        total += 1
        failed += d["status"] != "ok"
        print(jsonio.dumps(d) if args.json else _line(d))
    if failed:
        print(f"slamrun: {failed} of {total} file(s) could not be evaluated (status not ok)", file=sys.stderr)
        return 1
    return 0


def _same_sequence(folder: Path, trajectories: list[Path]) -> None:
    """Refuse a campaign run's trajectory (run.json beside it) made on other data than `folder`'s: by the data
    digest its run.json records (the run key's `<sequence>@<data>`), or by its sequence's name where it records
    none (an older run). What was not checked, or passed on another name, is said in a note."""
    name = folder.resolve().name
    digest = None  # the folder's (computed once, when a run records one: its small files, its frames' list)
    for traj in trajectories:
        record = Path(traj).parent / RUN_RECORD
        run = _run_record(record, traj, folder)
        if run is None:
            continue  # not a run's folder: evaluated as any file
        sequence = run.get("sequence") if isinstance(run.get("sequence"), str) else None
        data = run.get("data")
        other_name = sequence is not None and sequence != name
        named = f"is of sequence {_quoted(sequence)}, not of {folder} ({_quoted(name)})" if other_name else ""
        if isinstance(data, str):
            from slamrun.datasets.layouts import sequence_identity

            digest = digest or sequence_identity(folder)
            if data == digest:
                if other_name:
                    _note(f"{traj}: its run ({record}) {named}: the same data (digest {digest!r}), evaluated")
                continue
            what = f"{named}: other data" if other_name else f"is of other data than {folder}, of the same name"
            raise SlamRunError(
                f"{traj}: its run ({record}) {what} (the run's data digest {_quoted(data)}, the folder's "
                f"{digest!r}); give the folder of the run's sequence with --gt, or --any-sequence to evaluate it "
                "against this one anyway"
            )
        if other_name:
            raise SlamRunError(
                f"{traj}: its run ({record}) {named}; give that sequence's folder with --gt, or --any-sequence to "
                "evaluate it against this one anyway"
            )
        checked = "by its sequence's name only" if sequence is not None else "not checked (nor its sequence's name)"
        _note(f"{traj}: its run ({record}) records no data digest (an older run?): its sequence {checked}")


MAX_RUN_JSON = 2**20  # bytes: a run's record is a few KiB


def _run_record(record: Path, traj: Path, folder: Path) -> dict | None:
    """The run.json beside a trajectory as a dict; None where there is none, or (said in a note) where it is no
    run's record: not a readable regular file of at most 1 MiB, not JSON, not a JSON object."""
    if not os.path.lexists(record):
        return None
    unchecked = f"{traj} evaluated, its sequence not checked against {folder}"
    try:
        run = json.loads(read_bounded(record, MAX_RUN_JSON, "a run's record").decode())
    except SlamRunError as exc:
        _note(f"{exc}: {unchecked}")
        return None
    except (ValueError, RecursionError):  # undecodable or not JSON (or nested beyond the parser)
        _note(f"{record}: not JSON, not a run's record: {unchecked}")
        return None
    if not isinstance(run, dict):
        _note(f"{record}: not a JSON object, not a run's record: {unchecked}")
        return None
    return run


QUOTE_MAX = 80  # characters of a value read from a file that a message quotes (then its start, said cut)


def _quoted(value: str) -> str:
    """`value` quoted as Python does (repr), its start only where it is long: at most about 120 characters."""
    text = repr(value)
    if len(text) <= QUOTE_MAX + 2:
        return text
    return f"{text[: QUOTE_MAX + 1]}... (cut: {len(value):,} characters)"


def _note(text: str) -> None:
    print(f"slamrun: note: {text}", file=sys.stderr)


def _folder_form_only(args) -> None:
    """A sequence folder is evaluated as the campaign does: options that would change that are refused."""
    given = [
        name
        for name, value in (
            ("--gt-format", args.gt_format),
            ("--times", args.times),
            ("--tolerance", args.tolerance),
        )
        if value is not None
    ]
    if given:
        raise SlamRunError(
            f"{args.gt}: a sequence folder is evaluated as a campaign does (its reader, its frame times, "
            f"association within 1 ms); {', '.join(given)}: for a ground-truth file as it is (give "
            "the file itself, e.g. --gt FOLDER/groundtruth.txt, for other settings)"
        )


def _options(args, gt, metrics: tuple[str, ...]):
    from slamrun.core.batch_eval import Options
    from slamrun.core.evaluation import ASSOCIATION_TOLERANCE_S
    from slamrun.core.metrics import DEFAULT_TOLERANCE_S

    kitti_possible = args.est_format in ("kitti", RECOGNISED) and gt.frame_times is not None
    times = tuple(gt.frame_times) if kitti_possible else None
    frames = tuple(gt.frame_times) if gt.frame_times is not None else None
    if args.delta_unit == "frames" and frames is None:
        raise SlamRunError(
            f"{args.gt}: --delta-unit frames counts the sequence's frames: give its frame times with --times FILE, "
            "or the sequence folder; or another unit (s, m, evo-f for evo's steps of the estimate's poses)"
        )
    default = gt.default_rpe
    rpe = {
        "delta": args.delta or (1.0 if args.delta_unit else default.delta),
        "delta_unit": args.delta_unit or default.unit,
    }
    if gt.is_folder:
        return Options(
            metrics=metrics,
            alignment=args.align or "sim3",
            tolerance_s=ASSOCIATION_TOLERANCE_S,
            est_format=args.est_format,
            times=times,
            frame_times=frames,
            campaign=True,  # each file as a campaign evaluates a run (core.metric_table.campaign_figures)
            **rpe,
        )
    return Options(
        metrics=metrics,
        alignment=args.align or "sim3",
        tolerance_s=DEFAULT_TOLERANCE_S if args.tolerance is None else args.tolerance,
        est_format=args.est_format,
        times=times,
        frame_times=frames,
        **rpe,
    )


def _line(d: dict) -> str:
    vals = " ".join(f"{k}={v:.6g}" for k, v in d.items() if isinstance(v, float))
    detail = f" ({_detail(d)})" if d.get("detail") else ""
    return f"{d['file']}: {d['status']}" + (f" {vals}" if vals else "") + detail


def _detail(d: dict) -> str:
    """A result's detail without the file its line already names: "line 1: 12 values, ..." for "FILE:1: ..."."""
    text = str(d["detail"])
    rest = text.removeprefix(f"{d['file']}:")
    if rest == text:
        return text
    line, sep, why = rest.partition(": ")
    return f"line {line}: {why}" if sep and line.isdigit() else rest.strip()
