"""Spec validation lists every problem at once, with its location."""

import json

import pytest
import yaml

from runner.cli import main
from runner.engine.plan import plan
from runner.engine.spec import load_spec
from runner.errors import SpecError
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
    assert "methods[2].name: unknown method 'dsoo' (known: " in msg
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
