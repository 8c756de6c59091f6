"""Spec validation lists every problem at once, with its location."""

import json

import pytest
import yaml

from slamrun.cli import main
from slamrun.engine.plan import plan
from slamrun.engine.spec_file import load_spec
from slamrun.errors import SpecError
from tests.conftest import fake_method, write_spec


def test_every_problem_listed_at_once(tmp_path, tiny_dataset):
    spec = {
        "name": "bad",
        "datasets": [
            {"name": "x", "path": str(tmp_path / "nowhere"), "sequences": ["s1"]},
            {"name": "y", "path": str(tiny_dataset), "sequences": ["seq_a", "missing_seq"]},
        ],
        "methods": [fake_method(), {"name": "external", "params": {"argv": ["x"], "colour": "red"}}, {"name": "dsoo"}],
        "trials": 0,
        "lanse": 2,
    }
    p = tmp_path / "s.yaml"
    p.write_text(yaml.safe_dump(spec))
    with pytest.raises(SpecError) as err:
        load_spec(p)
    msg = str(err.value)
    assert "methods[2].name: unknown method 'dsoo'; did you mean 'dso'? (known: " in msg
    assert "methods[1].params.colour: unknown parameter" in msg
    assert "lanse: unknown key" in msg
    assert "trials: Input should be greater than or equal to 1" in msg
    assert "methods[1].label: 'external' used by methods[0]" in msg
    assert len(err.value.problems) >= 5


def test_missing_dataset_folder_and_sequence(tmp_path, tiny_dataset):
    spec = {
        "name": "bad",
        "methods": [fake_method()],
        "datasets": [
            {"name": "x", "path": str(tmp_path / "nowhere"), "sequences": ["s1"]},
            {"name": "y", "path": str(tiny_dataset), "sequences": ["missing_seq"]},
        ],
    }
    p = tmp_path / "s.yaml"
    p.write_text(yaml.safe_dump(spec))
    with pytest.raises(SpecError) as err:
        load_spec(p)
    assert "datasets[0].path: folder" in str(err.value) and "not found" in str(err.value)
    assert "datasets[1].sequences[0]:" in str(err.value)


def test_yaml_syntax_error_names_line(tmp_path):
    p = tmp_path / "s.yaml"
    p.write_text("name: x\nmethods: [\n")
    with pytest.raises(SpecError, match="line 3"):
        load_spec(p)


def test_validate_cli_exit_codes(tmp_path, tiny_dataset, capsys):
    good = write_spec(tmp_path, tiny_dataset, [fake_method()])
    assert main(["validate", str(good)]) == 0
    assert "4 runs" in capsys.readouterr().out
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: x\ndatasets: []\nmethods: [{name: nope}]\n")
    assert main(["validate", str(bad)]) == 1
    err = capsys.readouterr().err
    assert "methods[0].name: unknown method 'nope'" in err and "datasets:" in err


def test_schema_is_json_schema(capsys):
    assert main(["schema"]) == 0
    schema = json.loads(capsys.readouterr().out)
    assert schema["additionalProperties"] is False and "methods" in schema["properties"]
    assert schema["properties"]["trials"]["description"]


def test_plan_keys_are_stable_and_grow(tmp_path, tiny_dataset):
    base = write_spec(tmp_path, tiny_dataset, [fake_method()], trials=2)
    keys2 = [r.key.id for r in plan(load_spec(base))]
    more = write_spec(tmp_path, tiny_dataset, [fake_method()], trials=3)
    keys3 = [r.key.id for r in plan(load_spec(more))]
    assert set(keys2) < set(keys3) and len(keys3) == 12
    changed = write_spec(tmp_path, tiny_dataset, [fake_method(sleep=0.5)], trials=2)
    keys_changed = {r.key.id for r in plan(load_spec(changed))}
    assert not keys_changed & set(keys2)  # a result-affecting parameter makes new keys
    assert len({k.split("/")[0] for k in keys_changed}) == 1


def test_distributed_spec(tmp_path, tiny_dataset):
    ok = load_spec(write_spec(tmp_path, tiny_dataset, [fake_method()], distributed={"address": "tcp://head:8786"}))
    assert ok.distributed.engine == "dask" and ok.distributed.address == "tcp://head:8786"
    bad = write_spec(
        tmp_path,
        tiny_dataset,
        [fake_method()],
        distributed={"engine": "spark", "address": "x"},
        measurement="exclusive",
    )
    with pytest.raises(SpecError) as err:
        load_spec(bad)
    msg = str(err.value)
    assert "distributed.engine: Input should be 'dask'" in msg
    timing = write_spec(
        tmp_path, tiny_dataset, [fake_method()], distributed={"address": "local"}, measurement="exclusive"
    )
    with pytest.raises(SpecError) as err:
        load_spec(timing)
    assert "'exclusive' (timing) needs one machine" in str(err.value)


TYPOS = """\
name: typos
trails: 2
backnd: docker
datasets:
  - name: e
    path: data
    layuot: euroc
    sequences: [MH_synth]
  - name: k
    path: kitti/sequences
    layout: kitti
    sequences: [00, 07, "08"]
  - name: x
    path: data
    layout: EuRoC
    sequences: MH_synth
methods:
  - name: reference_v0
  - name: colmap
    params: {strid: 3}
directions: [forwrd]
"""


def test_every_typo_gets_the_name_it_was_meant_to_be_in_line_order(tmp_path):
    """A newcomer's typos, each answered with the close name (case-insensitively), in the file's line order,
    without pydantic's "Value error, " prefix; KITTI's 00 (a number to YAML) is told to be quoted."""
    (tmp_path / "spec.yaml").write_text(TYPOS)
    with pytest.raises(SpecError) as err:
        load_spec(tmp_path / "spec.yaml", check_files=False)
    known = "cnn_dso, cnn_svo, colmap, df_orb_slam, dpvo, droid_slam, dsm, dso, dynaslam, external, glomap, ldso"
    assert err.value.problems == [
        "line 2: trails: unknown key; did you mean 'trials'?",
        "line 3: backnd: unknown key; did you mean 'backend'?",
        "line 7: datasets[0].layuot: unknown key; did you mean 'layout'?",
        'line 12: datasets[1].sequences[0]: 0 is a number to YAML, not a folder name: quote it: "00"',
        'line 12: datasets[1].sequences[1]: 7 is a number to YAML, not a folder name: quote it: "07"',
        "line 15: datasets[2].layout: unknown layout 'EuRoC'; did you mean 'euroc'? (known: tum-mono, euroc, kitti, "
        "tum-rgbd, tum-vi, icl-nuim, tartanair)",
        f"line 18: methods[0].name: unknown method 'reference_v0'; did you mean 'reference_vo'? (known: {known}, "
        "lsd_slam, mast3r_slam, orb_slam2, orb_slam3, reference_vo, svo)",
        "line 20: methods[1].params.strid: unknown parameter; did you mean 'stride'?",
        "line 21: directions[0]: Input should be 'forward' or 'backward'; did you mean 'forward'?",
    ]
    assert not any("Value error" in p for p in err.value.problems)


def test_problems_are_sorted_by_line_whichever_check_found_them(tmp_path):
    """The method checks run after the schema's: their problems still come in the file's order."""
    (tmp_path / "spec.yaml").write_text(
        "name: order\nmethods:\n  - name: nope\ndatasets:\n  - {name: d, path: ., sequences: [a]}\nlanse: 2\n"
    )
    with pytest.raises(SpecError) as err:
        load_spec(tmp_path / "spec.yaml", check_files=False)
    lines = [int(p.split(":")[0].removeprefix("line ")) for p in err.value.problems]
    assert lines == sorted(lines) == [3, 6], err.value.problems


def test_a_missing_sequence_names_the_close_one_and_lists_those_present(tmp_path, tiny_dataset):
    spec = write_spec(tmp_path, tiny_dataset, [fake_method()], datasets=[
        {"name": "d", "path": str(tiny_dataset), "sequences": ["seq_aa", "sqe_b", "other"]},
    ])  # fmt: skip
    with pytest.raises(SpecError) as err:
        load_spec(spec)
    holds = f"({tiny_dataset} holds seq_a, seq_b)"
    assert [p.split(": ", 1)[1] for p in err.value.problems] == [
        f"datasets[0].sequences[0]: {tiny_dataset / 'seq_aa'} not found; did you mean 'seq_a'? {holds}",
        f"datasets[0].sequences[1]: {tiny_dataset / 'sqe_b'} not found; did you mean 'seq_b'? {holds}",
        f"datasets[0].sequences[2]: {tiny_dataset / 'other'} not found {holds}",
    ]


def test_one_sequence_name_is_a_list_of_one(tmp_path, tiny_dataset):
    spec = write_spec(tmp_path, tiny_dataset, [fake_method()], datasets=[
        {"name": "d", "path": str(tiny_dataset), "sequences": "seq_a"},
    ])  # fmt: skip
    assert load_spec(spec).datasets[0].sequences == ["seq_a"]


def test_plan_counts_the_views_and_sequences_not_generated_yet(tmp_path, capsys):
    """Two synthetic sequences not generated yet, forward and backward: 4 views of 2 sequences (it said "4 of
    synthetic sequences")."""
    data = {"name": "s", "path": str(tmp_path / "data"), "sequences": ["a", "b"], "synthetic": {"frames": 30}}
    spec = write_spec(tmp_path, tmp_path / "data", [fake_method()], datasets=[data])
    assert main(["plan", str(spec)]) == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "and 4 view(s) of 2 synthetic sequence(s) generated on first use (their size is known once generated)" in out
