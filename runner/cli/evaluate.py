"""slamrun evaluate: metrics of trajectory files against a ground truth (TUM-Mono's, ATE, RPE, KITTI's), on every
core. The ground truth is a sequence folder (evaluated exactly as a campaign evaluates its runs) or a file as it is.
Exit 0 when every file was evaluated, 1 when any could not be (said on stderr with how many)."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from runner.core import jsonio
from runner.errors import SlamRunError

GT_FORMATS = ("tum-mono", "tum", "euroc", "kitti")
METRIC_CHOICES = ("tum-mono", "ate", "rpe", "kitti")


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
        "kitti (poses, with --times); default: recognised from its first row",
    )
    e.add_argument(
        "--metric",
        action="append",
        choices=METRIC_CHOICES,
        help="a metric (repeat for several); default: the dataset's (a folder's layout: tum-mono for TUM-Mono, ate "
        "and rpe, and kitti for KITTI), for a file its format's (tum-mono for a TUM file)",
    )
    e.add_argument("--align", help="sim3 (monocular, default), se3, none, first:N, se3:first:N")
    e.add_argument("--delta", type=_positive_float, help="RPE: the step between the poses of a pair (default 1)")
    e.add_argument("--delta-unit", choices=("frames", "m"), help="RPE: the step's unit (default frames)")
    e.add_argument(
        "--tolerance", type=_tolerance, help="association: largest time difference in s (default 0.02; a folder: 1 ms)"
    )
    e.add_argument("--est-format", choices=("tum", "kitti"), default="tum", help="the estimates' format")
    e.add_argument(
        "--times", type=Path, help="frame times (KITTI's times.txt) for KITTI poses with a ground-truth file"
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
        raise argparse.ArgumentTypeError(f"{text!r}: expected a whole number of processes, at least 1")
    return n


def _finite(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        v = math.nan
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"{text!r}: expected a finite number")
    return v


def _tolerance(text: str) -> float:
    v = _finite(text)
    if v < 0:
        raise argparse.ArgumentTypeError(f"{text!r}: expected seconds, 0 or more")
    return v


def _positive_float(text: str) -> float:
    v = _finite(text)
    if v <= 0:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a number above 0")
    return v


def cmd_evaluate(args) -> int:
    from runner.core.batch_eval import evaluate_files, keep_freed_memory
    from runner.core.metrics import Alignment
    from runner.datasets.groundtruth import open_groundtruth

    keep_freed_memory()
    Alignment.parse(args.align or "sim3")  # a bad --align is named before any file is read
    metrics = tuple(dict.fromkeys(args.metric)) if args.metric else None
    if args.gt.is_dir():
        _folder_form_only(args)
    elif args.est_format == "kitti" and args.times is None:
        raise SlamRunError("KITTI poses carry no timestamps: give the sequence's times.txt with --times")
    gt = open_groundtruth(args.gt, args.gt_format, metrics, args.times)
    for note in gt.notes:
        print(f"slamrun: note: {note}", file=sys.stderr)
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


def _folder_form_only(args) -> None:
    """A sequence folder is evaluated as the campaign does: options that would change that are refused."""
    given = [
        name
        for name, value in (
            ("--gt-format", args.gt_format),
            ("--times", args.times),
            ("--delta", args.delta),
            ("--delta-unit", args.delta_unit),
            ("--tolerance", args.tolerance),
        )
        if value is not None
    ]
    if given:
        raise SlamRunError(
            f"{args.gt}: a sequence folder is evaluated as a campaign does (its reader, its frame times, RPE one "
            f"frame apart, association within 1 ms); {', '.join(given)}: for a ground-truth file as it is (give "
            "the file itself, e.g. --gt FOLDER/groundtruth.txt, for other settings)"
        )


def _options(args, gt, metrics: tuple[str, ...]):
    from runner.core.batch_eval import Options
    from runner.core.evaluation import ASSOCIATION_TOLERANCE_S
    from runner.core.metrics import DEFAULT_TOLERANCE_S

    times = tuple(gt.frame_times) if args.est_format == "kitti" else None
    if gt.is_folder:
        from runner.engine.execute import evaluate

        return Options(
            metrics=metrics,
            alignment=args.align or "sim3",
            tolerance_s=ASSOCIATION_TOLERANCE_S,
            est_format=args.est_format,
            times=times,
            campaign=evaluate,
        )
    return Options(
        metrics=metrics,
        alignment=args.align or "sim3",
        delta=args.delta or 1.0,
        delta_unit=args.delta_unit or "frames",
        tolerance_s=DEFAULT_TOLERANCE_S if args.tolerance is None else args.tolerance,
        est_format=args.est_format,
        times=times,
    )


def _line(d: dict) -> str:
    vals = " ".join(f"{k}={v:.6g}" for k, v in d.items() if isinstance(v, float))
    detail = f" ({d['detail']})" if d.get("detail") else ""
    return f"{d['file']}: {d['status']}" + (f" {vals}" if vals else "") + detail
