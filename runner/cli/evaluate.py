"""slamrun evaluate: a metric of trajectory files against a ground truth (TUM-Mono's, ATE, RPE, KITTI's), on
every core."""

from __future__ import annotations

from pathlib import Path

from runner.core import jsonio
from runner.errors import SlamRunError

GT_FORMATS = ("tum-mono", "tum", "euroc", "kitti")


def add_commands(sub) -> None:
    e = sub.add_parser("evaluate", help="a metric of trajectory files against a ground truth")
    e.add_argument(
        "--gt", type=Path, required=True, help="the ground truth (groundtruthSync.txt, TUM, EuRoC csv, KITTI)"
    )
    e.add_argument(
        "--gt-format",
        choices=GT_FORMATS,
        help="tum-mono (groundtruthSync, NaN rows kept), tum, euroc (state csv, ns), kitti (poses, with --times); "
        "default: tum-mono for the tum-mono metric, euroc for a .csv, else tum",
    )
    e.add_argument("--metric", choices=("tum-mono", "ate", "rpe", "kitti"), default="tum-mono", help="the metric")
    e.add_argument("--align", default="sim3", help="sim3 (monocular, default), se3, none, first:N, se3:first:N")
    e.add_argument("--delta", type=float, default=1.0, help="RPE: the step between the poses of a pair")
    e.add_argument("--delta-unit", choices=("frames", "m"), default="frames", help="RPE: the step's unit")
    e.add_argument("--tolerance", type=float, default=0.02, help="association: largest time difference (s)")
    e.add_argument("--est-format", choices=("tum", "kitti"), default="tum", help="the estimates' format")
    e.add_argument("--times", type=Path, help="frame times (KITTI's times.txt) for KITTI poses")
    e.add_argument("--json", action="store_true", help="one JSON object per line")
    e.add_argument("traj", type=Path, nargs="+", help="trajectory files")
    e.add_argument("--jobs", type=int, help="worker processes (default: every core); output stays in input order")
    e.set_defaults(func=cmd_evaluate)


def cmd_evaluate(args) -> int:
    from runner.core.batch_eval import Options, evaluate_files, keep_freed_memory
    from runner.core.metrics import Alignment

    keep_freed_memory()
    if args.metric == "tum-mono" and args.gt_format not in (None, "tum-mono"):
        raise SlamRunError("--metric tum-mono needs a TUM-Mono groundtruthSync.txt (--gt-format tum-mono)")
    needs_times = args.est_format == "kitti" or args.gt_format == "kitti"
    if needs_times and args.times is None:
        raise SlamRunError("KITTI poses carry no timestamps: give the sequence's times.txt with --times")
    Alignment.parse(args.align)  # a bad --align is named before any file is read
    times = _times(args.times) if args.times else None
    gt = _groundtruth(args, times)
    opts = Options(
        metric=args.metric,
        alignment=args.align,
        delta=args.delta,
        delta_unit=args.delta_unit,
        tolerance_s=args.tolerance,
        est_format=args.est_format,
        times=tuple(times) if times is not None and args.est_format == "kitti" else None,
    )
    for d in evaluate_files(gt, args.traj, args.jobs, opts):
        if args.json:
            print(jsonio.dumps(d))
        else:
            vals = " ".join(f"{k}={v:.6g}" for k, v in d.items() if isinstance(v, float))
            detail = d.get("detail")
            print(f"{d['file']}: {d['status']} {vals}" + (f"({detail})" if detail else ""))
    return 0


def _times(path: Path):
    from runner.core.trajectory import read_times

    return read_times(path)


def _groundtruth(args, times):
    import numpy as np

    from runner.core.trajectory import Trajectory, read_euroc_csv, read_kitti, read_tum

    fmt = args.gt_format or (
        "tum-mono" if args.metric == "tum-mono" else "euroc" if args.gt.suffix == ".csv" else "tum"
    )
    if not args.gt.is_file():
        raise SlamRunError(f"{args.gt}: ground truth not found")
    if fmt == "tum-mono":  # NaN rows kept: they split the benchmark's segments
        data = np.loadtxt(args.gt, comments="#", ndmin=2)
        if data.shape[1] != 8:
            raise SlamRunError(f"{args.gt}: expected a groundtruthSync file of 'timestamp tx ty tz qx qy qz qw' rows")
        return Trajectory(data[:, 0], data[:, 1:4], data[:, 4:8])
    if fmt == "euroc":
        return read_euroc_csv(args.gt)
    if fmt == "kitti":
        return read_kitti(args.gt, times)
    return read_tum(args.gt)
