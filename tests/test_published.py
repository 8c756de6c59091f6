"""Published figures beside a campaign's: DPVO's and DPV-SLAM's logs read from the files of its repository (copied
byte for byte into slamrun/methods/dpvo/published), a lab's own CSV, and the report and `slamrun stats` printing
them beside a real campaign's medians, marked as published and never tested."""

from __future__ import annotations

import re
import tarfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from slamrun.analysis.published import beside, default_params
from slamrun.errors import SlamRunError
from slamrun.results.published import Published, built_in, read_dpvo_log, read_table, same_sequence

LOGS = Path(__file__).resolve().parent.parent / "slamrun" / "methods" / "dpvo" / "published"
ARCHIVE = "DPVO-859bbbfdac6c6185f345003b3c473901fcd13ace.tar.gz"


def _stated_medians(text: str) -> dict[str, float]:
    """The log's own summary lines (`name value`), read apart from slamrun's reader."""
    return {m.group(1): float(m.group(2)) for m in re.finditer(r"^(\w+) ([0-9.]+)$", text, re.MULTILINE)}


def test_the_logs_are_dpvos_own_files(shared_data):
    """Byte for byte the logs of the pinned archive in ../shared/upstream."""
    archive = shared_data.parent / "upstream" / ARCHIVE
    if not archive.is_file():
        pytest.skip(reason=f"{archive} not found: the pinned upstream archives live in shared/upstream beside the repo")
    manifest = yaml.safe_load((LOGS / "manifest.yaml").read_text())
    with tarfile.open(archive) as tar:
        for log in manifest["logs"]:
            member = tar.extractfile(f"{ARCHIVE.removesuffix('.tar.gz')}/logs/{log['file']}")
            assert member.read() == (LOGS / log["file"]).read_bytes(), log["file"]


def test_dpvos_euroc_medians_equal_the_logs_own_summary_lines():
    figures = built_in()
    dpvo = [f for f in figures if f.method == "dpvo" and not f.settings["loop_closure"]]
    euroc = {f.sequence: f for f in dpvo if f.dataset == "euroc"}
    stated = _stated_medians((LOGS / "euroc.txt").read_text())
    assert len(euroc) == 11 and set(euroc) == set(stated)
    for name, value in stated.items():
        assert euroc[name].value == value and euroc[name].runs == 5
    protocol = "published, 5 runs, median ATE RMSE (m), Sim(3), all frames, loop_closure=False"
    assert euroc["MH_01_easy"].protocol() == protocol
    assert euroc["MH_01_easy"].source.endswith("@859bbbfdac6c6185f345003b3c473901fcd13ace/logs/euroc.txt")
    assert {f.settings["loop_closure"] for f in euroc.values()} == {False}
    slam = {f.sequence: f for f in figures if f.settings.get("loop_closure") and f.dataset == "euroc"}
    assert {s: f.value for s, f in slam.items()} == _stated_medians((LOGS / "dpv_slam" / "euroc.txt").read_text())
    assert slam["MH_01_easy"].method == "dpvo"
    assert slam["MH_01_easy"].protocol().endswith("all frames, loop_closure=True")
    assert {f.dataset for f in figures} == {"euroc", "tum-rgbd", "tartanair", "icl-nuim"}


def test_a_log_whose_summary_disagrees_with_its_runs_is_refused():
    text = (LOGS / "euroc.txt").read_text().replace("MH_01_easy 0.08683937293607617", "MH_01_easy 0.07")
    with pytest.raises(SlamRunError, match="MH_01_easy: the log states 0.07 where its runs' median is 0.0868"):
        read_dpvo_log(text, method="dpvo", dataset="euroc", source="x", metric="ate_rmse", statistic="median",
                      alignment="sim3", frames="all")  # fmt: skip


def test_sequences_match_by_name_prefix_or_suffix():
    assert same_sequence("rgbd_dataset_freiburg1_desk", "desk") and not same_sequence(
        "rgbd_dataset_freiburg1_desk2", "desk"
    )
    assert same_sequence("MH_01", "MH_01_easy") and same_sequence("mh_01_easy", "MH_01_easy")
    assert not same_sequence("MH_01_easy", "MH_02_easy")


def _runs(method_name: str, sequence: str, values: list[float], alignment: str = "sim3") -> list[dict]:
    return [
        {"method": method_name, "method_name": method_name, "dataset": "euroc", "sequence": sequence,
         "direction": "forward", "trial": i, "status": "done", "ate_rmse": v,
         "eval_settings": f'{{"alignment": "{alignment}"}}'}
        for i, v in enumerate(values)
    ]  # fmt: skip


def test_a_campaigns_median_stands_beside_the_published_figure_with_the_protocol_said():
    df = pd.DataFrame(_runs("dpvo", "MH_01_easy", [0.05, 0.07, 0.09]) + _runs("dpvo", "V9_99", [0.1]))
    table = beside(df, built_in())
    assert len(table) == 1
    row = table.iloc[0]
    assert (row.method, row.sequence, row.metric, row.runs) == ("dpvo", "MH_01_easy", "ate_rmse", 3)
    assert row["this campaign, median"] == pytest.approx(0.07)
    assert row.published == pytest.approx(0.08683937293607617)
    assert row["published as"].startswith("published, 5 runs, median ATE") and row["protocol differs"] == "-"
    se3 = beside(pd.DataFrame(_runs("dpvo", "MH_01_easy", [0.05], "se3")), built_in()).iloc[0]
    assert se3["protocol differs"] == "aligned by SE(3) here"


def test_dpv_slams_figures_stand_beside_dpvo_run_with_its_loop_closure_only():
    """DPV-SLAM is DPVO with loop_closure: true. A campaign running both (labels dpvo and dpv_slam) sees each beside
    its own published figure; DPVO's figure is never set beside the loop-closing runs, nor DPV-SLAM's beside DPVO's."""
    runs = _runs("dpvo", "MH_01_easy", [0.05, 0.07]) + [
        r | {"method": "dpv_slam"} for r in _runs("dpvo", "MH_01_easy", [0.02, 0.04])
    ]
    params = {"dpvo": default_params("dpvo"), "dpv_slam": default_params("dpvo") | {"loop_closure": True}}
    table = beside(pd.DataFrame(runs), built_in(), params).set_index("method")
    slam_log = _stated_medians((LOGS / "dpv_slam" / "euroc.txt").read_text())
    assert table.loc["dpvo", "published"] == pytest.approx(0.08683937293607617)
    assert table.loc["dpv_slam", "published"] == pytest.approx(slam_log["MH_01_easy"])
    assert table.loc["dpv_slam", "this campaign, median"] == pytest.approx(0.03)
    assert table.loc["dpv_slam", "published as"].endswith("loop_closure=True")
    assert len(table) == 2


def test_a_lab_figure_names_its_settings_in_one_cell(tmp_path):
    path = tmp_path / "ours.csv"
    header = "method,dataset,sequence,metric,value,runs,statistic,alignment,frames,source,settings"
    row = "dpvo,euroc,MH_01_easy,ate_rmse,0.02,3,median,sim3,all,our paper"
    path.write_text(f"{header}\n{row},loop_closure=true; stride=1\n")
    (figure,) = read_table(path)
    assert figure.settings == {"loop_closure": True, "stride": 1}
    assert figure.made_with({"loop_closure": True, "stride": 1, "seed": None})
    assert not figure.made_with({"loop_closure": True, "stride": 2}) and not figure.made_with(None)
    path.write_text(f"{header}\n{row},loop_closure\n")
    with pytest.raises(SlamRunError, match=r"line 2: settings: .*expected name=value pairs"):
        read_table(path)


@pytest.mark.parametrize(
    ("row", "expected"),
    [
        ({"value": "x"}, "line 2: value: Input should be a valid number"),
        ({"statistic": "best"}, "line 2: statistic: Input should be 'median', 'mean' or 'single'"),
        ({"metric": "ate"}, "line 2: metric 'ate' is no results column"),
    ],
)
def test_a_wrong_reference_file_is_named_with_its_line(tmp_path, row, expected):
    good = {"method": "reference_vo", "dataset": "euroc", "sequence": "V1_synth", "metric": "ate_rmse",
            "value": "0.1", "runs": "5", "statistic": "median", "alignment": "sim3", "frames": "all",
            "source": "our paper, Table 2"}  # fmt: skip
    path = tmp_path / "published.csv"
    pd.DataFrame([good | row]).to_csv(path, index=False)
    with pytest.raises(SlamRunError) as err:
        read_table(path)
    assert str(path) in str(err.value) and expected in str(err.value)
    pd.DataFrame([good]).to_csv(path, index=False)
    assert read_table(path) == [Published(**good)]


def test_a_real_campaign_shows_a_labs_reference_file_in_its_report_and_stats(tmp_path, capsys):
    """reference_vo on a synthetic EuRoC sequence, with a lab's CSV naming it: the report's table and `slamrun
    stats` show the published figure beside the campaign's median; the study's tests do not change."""
    from slamrun.analysis.report import write_report
    from slamrun.cli import main
    from slamrun.engine.campaign import run_campaign
    from slamrun.engine.spec_file import load_spec

    csv = tmp_path / "ours.csv"
    pd.DataFrame([{"method": "reference_vo", "dataset": "euroc", "sequence": "MH_01_easy", "metric": "ate_rmse",
                   "value": 0.123, "runs": 3, "statistic": "median", "alignment": "se3", "frames": "all",
                   "source": "our 2025 paper, Table 2"}]).to_csv(csv, index=False)  # fmt: skip
    spec = {
        "name": "pub",
        "results": str(tmp_path / "results"),
        "cache": str(tmp_path / "cache"),
        "datasets": [
            {
                "name": "euroc",
                "layout": "euroc",
                "path": str(tmp_path / "data"),
                "sequences": ["MH_01"],
                "synthetic": {"frames": 60, "seed": 3},
            }
        ],  # fmt: skip
        "methods": [{"name": "reference_vo"}],
        "directions": ["forward"],
        "published": ["ours.csv"],
        "report": False,
    }
    path = tmp_path / "spec.yaml"
    path.write_text(yaml.safe_dump(spec))
    run_campaign(load_spec(path), log=lambda *a: None)
    index = write_report(tmp_path / "results")
    table = pd.read_csv(index.parent / "tables" / "published.csv")
    assert list(table.method) == ["reference_vo"] and list(table.sequence) == ["MH_01"]
    assert table.published.iloc[0] == 0.123 and table["protocol differs"].iloc[0] == "aligned by Sim(3) here"
    assert "Published figures beside this campaign" in index.read_text()
    runs = pd.read_csv(tmp_path / "results" / "results.csv")
    assert table["this campaign, median"].iloc[0] == pytest.approx(np.median(runs.ate_rmse))
    capsys.readouterr()
    assert main(["stats", str(tmp_path / "results")]) == 0
    out = capsys.readouterr().out
    assert "published figures beside this campaign's (euroc; shown, never tested):" in out
    assert "reference_vo MH_01 ate_rmse: median" in out and "published, 3 runs, median ATE RMSE (m), SE(3)" in out


def test_a_spec_naming_an_unreadable_reference_file_is_refused_before_anything_runs(tmp_path):
    from slamrun.engine.spec_file import load_spec

    spec = {"name": "pub", "results": str(tmp_path / "results"),
            "datasets": [{"name": "euroc", "layout": "euroc", "path": str(tmp_path / "data"), "sequences": ["MH_01"],
                          "synthetic": {"frames": 60, "seed": 3}}],
            "methods": [{"name": "reference_vo"}], "published": ["missing.csv"]}  # fmt: skip
    path = tmp_path / "spec.yaml"
    path.write_text(yaml.safe_dump(spec))
    with pytest.raises(SlamRunError, match=r"published\[0\]: .*missing.csv: published figures: not readable"):
        load_spec(path)


def test_stats_refuses_an_unreadable_reference_file_before_printing_anything(tmp_path, capsys):
    from slamrun.cli import main

    table = tmp_path / "results.csv"
    pd.DataFrame(_runs("dpvo", "MH_01_easy", [0.05, 0.07])).to_csv(table, index=False)
    assert main(["stats", str(table), "--published", str(tmp_path / "missing.csv")]) != 0
    captured = capsys.readouterr()
    assert "missing.csv: published figures: not readable" in captured.err and captured.out == ""


def test_each_labels_parameters_come_from_the_recorded_spec_with_their_defaults(tmp_path):
    """The spec as run names each label's method and parameters; method_params fills in the defaults, and a method
    not registered here (a plug-in since removed) is left out rather than guessed."""
    from slamrun.analysis.published import method_params

    methods = [
        {"name": "dpvo"},
        {"name": "dpvo", "label": "dpv_slam", "params": {"loop_closure": True}},
        {"name": "a_plugin_not_installed_here"},
    ]
    (tmp_path / "spec.resolved.yaml").write_text(yaml.safe_dump({"name": "c", "methods": methods}))
    params = method_params(tmp_path)
    assert set(params) == {"dpvo", "dpv_slam"}
    assert params["dpvo"] == default_params("dpvo") and params["dpvo"]["loop_closure"] is False
    assert params["dpv_slam"] == default_params("dpvo") | {"loop_closure": True}
    assert method_params(tmp_path / "results.csv") == params  # a results table names its folder
