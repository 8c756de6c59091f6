"""What every dataset reader shares (slamrun.datasets.sequence): the folder check, the one error listing a
sequence's problems, the text files checked before anything reads them, the ground truth read as a DatasetError,
the rows of a pose file; and the view's opposite direction, the mirror the cache links frames from."""

from __future__ import annotations

import pytest

from slamrun.core.trajectory import read_tum
from slamrun.datasets import euroc, tum_vi
from slamrun.datasets.layouts import open_sequence
from slamrun.datasets.make_synthetic import generate
from slamrun.datasets.sequence import (
    raise_problems,
    read_groundtruth,
    require_regular,
    row_count,
    sequence_folder,
)
from slamrun.datasets.view import Direction
from slamrun.errors import DatasetError


def test_a_sequence_folder_is_a_folder(tmp_path):
    assert sequence_folder(str(tmp_path)) == tmp_path
    with pytest.raises(DatasetError, match=rf"^{tmp_path / 'none'}: sequence folder not found$"):
        sequence_folder(tmp_path / "none")


def test_problems_are_one_error_named_by_the_layout(tmp_path):
    raise_problems(tmp_path, "KITTI", [])  # none: nothing raised
    with pytest.raises(DatasetError) as kitti:
        raise_problems(tmp_path, "KITTI", ["a: missing", "b: empty"])
    assert str(kitti.value) == f"{tmp_path}: invalid KITTI sequence:\n  a: missing\n  b: empty"
    with pytest.raises(DatasetError) as plain:
        raise_problems(tmp_path, "", ["a: missing"])
    assert str(plain.value) == f"{tmp_path}: invalid sequence:\n  a: missing"


def test_a_text_file_that_is_a_folder_is_refused_before_it_is_read(tmp_path):
    listing, absent = tmp_path / "rgb.txt", tmp_path / "groundtruth.txt"
    require_regular(tmp_path, "TUM RGB-D", [listing, absent])  # missing files are the reader's to name
    listing.mkdir()
    with pytest.raises(DatasetError, match=rf"invalid TUM RGB-D sequence:\n  {listing}: not a regular file"):
        require_regular(tmp_path, "TUM RGB-D", [listing, absent])


def test_the_ground_truth_reader_says_a_format_error_as_a_dataset_error(tmp_path):
    good, bad = tmp_path / "good.txt", tmp_path / "bad.txt"
    good.write_text("# t x y z qx qy qz qw\n1.0 0 0 0 0 0 0 1\n2.0 1 0 0 0 0 0 1\n")
    assert read_groundtruth(good, read_tum).positions.tolist() == [[0, 0, 0], [1, 0, 0]]
    bad.write_text("1.0 0 0\n")
    with pytest.raises(DatasetError):
        read_groundtruth(bad, read_tum)


def test_row_count_counts_the_lines_that_are_not_blank(tmp_path):
    path = tmp_path / "poses.txt"
    path.write_text("1 2 3\n\n   \n4 5 6\n7 8 9")
    assert row_count(path) == 3


def test_the_asl_layouts_hold_the_frame_list_their_reader_reads(tmp_path):
    assert euroc.LAYOUT.frame_list == tum_vi.LAYOUT.frame_list == "mav0/cam0/data.csv"
    folder = generate(tmp_path / "MH_01_easy", frames=20, seed=0, layout="euroc")
    assert euroc.LAYOUT.holds(folder) and open_sequence(folder).n_frames == 20


def test_each_direction_has_the_other_as_its_opposite():
    assert Direction.forward.opposite is Direction.backward
    assert Direction.backward.opposite is Direction.forward
    assert Direction("backward").opposite.opposite is Direction.backward
