"""The results catalogue: each column declared once, and every reader takes it from there (the metric table's
figures, the ledger's schema, results.csv, the terminal, the live page, the report's labels)."""

from __future__ import annotations

import sqlite3

import numpy as np
import pytest

from slamrun.core.evaluation import TumMonoResult
from slamrun.core.formats import read_trajectory
from slamrun.core.metric_table import METRICS, NAMES, Context
from slamrun.engine.export import COLUMNS, results_frame
from slamrun.engine.ledger import Ledger
from slamrun.results import catalogue
from slamrun.results.catalogue import CATALOGUE, METRIC_COLUMNS, RESOURCE_COLUMNS
from slamrun.results.vocabulary import EvalStatus


def test_every_metric_fills_exactly_its_catalogue_columns_on_real_files(shared_data):
    evo = shared_data / "evo_test_data"
    gt = read_trajectory(evo / "fr2_desk_groundtruth.txt", "tum")
    est = read_trajectory(evo / "fr2_desk_ORB.txt", "tum")
    ctx = Context()
    assert NAMES == catalogue.METRIC_NAMES
    times = np.loadtxt(evo / "KITTI_00_gt_times.txt")
    kitti = [read_trajectory(evo / f"KITTI_00_{w}.txt", "kitti", times=times) for w in ("gt", "ORB")]
    for name, m in METRICS.items():
        if name == catalogue.TUM_MONO:  # its own ground truth (groundtruthSync): its fields of a result
            result = TumMonoResult(EvalStatus.ok)
        else:  # fr2_desk is under KITTI's 100 m: KITTI's figures of KITTI 00
            result = m.result(*(kitti if name == catalogue.KITTI else (gt, est)), ctx)
        filled = set(m.fields(result)) | set(m.preset(ctx))
        assert filled == set(m.columns) and m.columns, (name, filled ^ set(m.columns))


def test_the_ledger_schema_and_results_csv_take_the_catalogue(tmp_path):
    ledger = Ledger(tmp_path / "ledger.sqlite")
    with sqlite3.connect(tmp_path / "ledger.sqlite") as db:
        types = {row[1]: row[2] for row in db.execute("PRAGMA table_info(runs)")}
    assert {c: types[c] for c in CATALOGUE} == {c.name: c.type for c in CATALOGUE.values()}
    assert [c for c in COLUMNS if c in CATALOGUE] == [*METRIC_COLUMNS, *RESOURCE_COLUMNS]
    assert list(results_frame(ledger).columns) == list(COLUMNS)
    ledger.close()


@pytest.mark.parametrize("name", catalogue.SUMMARY_METRICS)
def test_the_live_page_and_the_report_label_a_column_alike(name):
    from slamrun.serve.snapshot import LABELS

    assert LABELS[name] == catalogue.label(name) == catalogue.LABELS.get(name, name)


def test_roles_keep_the_orders_the_views_show():
    assert catalogue.MAIN_METRICS == ("e_align", "ate_rmse")
    assert catalogue.PROGRESS_METRICS[:2] == catalogue.MAIN_METRICS
    assert catalogue.STUDY_METRICS == ("e_t", "e_r", "e_s_sym", "e_start", "e_end", "e_rmse")
    assert all(catalogue.column(c).heading for c in catalogue.RESOURCES_TABLE)
    assert set(catalogue.RESOURCES_TABLE) <= set(RESOURCE_COLUMNS)
    for c in CATALOGUE.values():
        assert c.type in ("REAL", "INTEGER", "TEXT") and (not c.metric or c.metric in catalogue.METRIC_NAMES), c
