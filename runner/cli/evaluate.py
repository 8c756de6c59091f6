"""slamrun evaluate: the TUM-Mono metrics of trajectory files, on every core."""

from __future__ import annotations

import json
from pathlib import Path

from runner.errors import SlamRunError


def add_commands(sub) -> None:
    e = sub.add_parser("evaluate", help="TUM-Mono metrics of trajectory files against a ground truth")
    e.add_argument("--gt", type=Path, required=True, help="the sequence's groundtruthSync.txt")
    e.add_argument("--json", action="store_true", help="one JSON object per line")
    e.add_argument("traj", type=Path, nargs="+", help="TUM trajectory files")
    e.add_argument("--jobs", type=int, help="worker processes (default: every core); output stays in input order")
    e.set_defaults(func=cmd_evaluate)


def cmd_evaluate(args) -> int:
    import numpy as np

    from runner.core.batch_eval import evaluate_files
    from runner.core.trajectory import Trajectory

    data = np.loadtxt(args.gt, comments="#", ndmin=2) if args.gt.exists() else None
    if data is None or data.shape[1] != 8:
        raise SlamRunError(f"{args.gt}: expected a groundtruthSync file of 'timestamp tx ty tz qx qy qz qw' rows")
    gt = Trajectory(data[:, 0], data[:, 1:4], data[:, 4:8])
    for d in evaluate_files(gt, args.traj, args.jobs):
        if args.json:
            print(json.dumps(d))
        else:
            vals = " ".join(f"{k}={v:.6g}" for k, v in d.items() if isinstance(v, float))
            detail = d.get("detail")
            print(f"{d['file']}: {d['status']} {vals}" + (f"({detail})" if detail else ""))
    return 0
