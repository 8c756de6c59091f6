"""Bad ground truth is the dataset's fault, said before any run, never a method's: NaN rows in a TUM RGB-D or
ICL-NUIM ground truth (once dropped, and the runs evaluated on the frames left), a ground truth that matches no
frame (once charged to the method as `lost`), a zero quaternion (once `np.float64(5.0)` and no line)."""

from __future__ import annotations

import pytest

from slamrun.core.trajectory import read_tum
from slamrun.datasets.layouts import open_sequence
from slamrun.datasets.make_synthetic import generate
from slamrun.errors import DatasetError, TrajectoryFormatError


def corrupt_rows(path, every: int, value: str = "nan") -> int:
    """Replace the x of every `every`-th data row with `value`; returns the first such line's number."""
    lines = path.read_text().splitlines()
    data = [i for i, line in enumerate(lines) if line.strip() and not line.startswith("#")]
    for i in data[::every]:
        cells = lines[i].split()
        cells[1] = value
        lines[i] = " ".join(cells)
    path.write_text("\n".join(lines) + "\n")
    return data[0] + 1


@pytest.mark.parametrize("layout, gt_name", [("tum-rgbd", "groundtruth.txt"), ("icl-nuim", None)])
def test_nan_rows_in_the_ground_truth_are_refused_with_file_and_line(tmp_path, layout, gt_name):
    name = "rgbd_dataset_freiburg1_synth" if layout == "tum-rgbd" else "living_room_traj0_frei_png"
    folder = generate(tmp_path / name, frames=30, seed=0, layout=layout)
    gt = folder / gt_name if gt_name else next(folder.glob("*.gt.freiburg"))
    line = corrupt_rows(gt, 3)
    with pytest.raises(DatasetError, match=rf"{gt}:{line}: \d+ row\(s\) hold NaN"):
        open_sequence(folder).groundtruth()


def test_validate_names_it_before_any_run(tmp_path):
    import subprocess
    import sys

    import yaml

    folder = generate(tmp_path / "data" / "rgbd_dataset_freiburg1_synth", frames=30, seed=0, layout="tum-rgbd")
    corrupt_rows(folder / "groundtruth.txt", 2, "inf")
    spec = tmp_path / "spec.yaml"
    spec.write_text(
        yaml.safe_dump(
            {
                "name": "v",
                "results": str(tmp_path / "results"),
                "datasets": [
                    {"name": "d", "path": str(folder.parent), "sequences": [folder.name], "layout": "tum-rgbd"}
                ],
                "methods": [{"name": "reference_vo"}],
            }
        )
    )
    out = subprocess.run([sys.executable, "-m", "slamrun.cli", "validate", str(spec)], capture_output=True, text=True)
    assert out.returncode != 0 and "Traceback" not in out.stderr
    assert f"{folder / 'groundtruth.txt'}:" in out.stderr + out.stdout and "infinite" in out.stderr + out.stdout


def test_ground_truth_at_no_frame_is_the_datasets_error(tmp_path):
    folder = generate(tmp_path / "rgbd_dataset_freiburg1_synth", frames=30, seed=0, layout="tum-rgbd")
    gt = folder / "groundtruth.txt"
    lines = gt.read_text().splitlines()
    shifted = [
        line if line.startswith("#") else " ".join([f"{float(line.split()[0]) + 1000:.6f}", *line.split()[1:]])
        for line in lines
    ]
    gt.write_text("\n".join(shifted) + "\n")
    with pytest.raises(DatasetError, match="no ground-truth pose at any of the 30 frames' times"):
        open_sequence(folder).groundtruth()


def test_a_zero_quaternion_is_named_with_its_line(tmp_path):
    path = tmp_path / "traj.txt"
    path.write_text("# t x y z qx qy qz qw\n1 0 0 0 0 0 0 1\n5 0 0 0 0 0 0 0\n")
    with pytest.raises(TrajectoryFormatError) as err:
        read_tum(path)
    assert str(err.value) == f"{path}:3: a zero quaternion (no rotation) at timestamp 5"
