"""The report: tables and figures from a results table, and index.html rendered in headless Chromium."""

from __future__ import annotations

import contextlib
import itertools
import json
import os
import re
import shutil
import subprocess
from dataclasses import dataclass

import numpy as np
import pandas as pd
import pytest

from slamrun.analysis import figures
from slamrun.analysis.report import write_report
from slamrun.cli import main


def fake_results(tmp_path, n_methods=3, n_seq=4, trials=5) -> pd.DataFrame:
    """A results table shaped like a campaign's (values drawn at random: the report's inputs, not its goldens)."""
    rng = np.random.default_rng(1)
    rows = []
    for mi in range(n_methods):
        for s in range(n_seq):
            for d in ("forward", "backward"):
                for t in range(trials):
                    failed = rng.random() < 0.1
                    scale = 1 + mi
                    row = {
                        "method": f"m{mi}",
                        "sequence": f"sequence_{s:02d}",
                        "direction": d,
                        "trial": t,
                        "status": "failed" if failed else "done",
                        "failure": "lost" if failed else None,
                        "eval_status": None if failed else "ok",
                        "wall_s": rng.uniform(10, 20),
                        "fps": rng.uniform(20, 40),
                        "cpu_mean_pct": rng.uniform(50, 100),
                        "cpu_peak_pct": rng.uniform(100, 150),
                        "ram_peak_mb": rng.uniform(100, 300),
                        "gpu_mem_peak_mb": np.nan,
                        "run_dir": str(tmp_path / "nowhere"),
                    }
                    for m in ("e_t", "e_r", "e_start", "e_end", "e_rmse", "e_align"):
                        row[m] = np.nan if failed else rng.lognormal(np.log(0.1 * scale), 0.5)
                    row["e_s"] = np.nan if failed else rng.lognormal(0, 0.05 * scale)
                    row["e_s_sym"] = np.nan if failed else max(row["e_s"], 1 / row["e_s"])
                    rows.append(row)
    return pd.DataFrame(rows)


def test_report_files(tmp_path):
    fake_results(tmp_path).to_csv(tmp_path / "results.csv", index=False)
    index = write_report(tmp_path)
    tables = {p.name for p in (tmp_path / "report" / "tables").iterdir()}
    for name in (
        "table3_drift",
        "table4_segments",
        "table2_resources",
        "failures",
        "motion_bias",
        "table3_drift_forward",
        "table3_drift_backward",
        "e_align_per_sequence",
    ):
        assert {f"{name}.csv", f"{name}.md", f"{name}.tex"} <= tables
    figs = {p.name for p in (tmp_path / "report" / "figures").iterdir()}
    for name in (
        "cumulative_e_t",
        "cumulative_e_r",
        "cumulative_e_s_sym",
        "cumulative_e_start",
        "cumulative_e_end",
        "cumulative_e_align_motion_bias",
        "heatmap_e_align",
        "box_e_t",
    ):
        assert {f"{name}.png", f"{name}.svg"} <= figs
    assert (tmp_path / "report" / "statistics_forward.json").exists()
    html = index.read_text()
    assert html.count("<img") >= 13 and "Kruskal-Wallis" in html
    t3 = pd.read_csv(tmp_path / "report" / "tables" / "table3_drift.csv")
    assert t3.method.iloc[0] == "m0"  # best first
    assert list(t3.method.iloc[-3:]) == ["Kruskal-Wallis chi2", "Kruskal-Wallis df", "Kruskal-Wallis p"]
    st = json.loads((tmp_path / "report" / "statistics.json").read_text())["metrics"]["e_t"]
    assert t3.e_t.iloc[-1] == pytest.approx(st["kruskal_p"], rel=1e-12) and t3.e_t.iloc[-2] == st["kruskal_df"]
    assert t3.e_t.dtype.kind == "f" and t3.runs.iloc[0] > 0  # numbers, the letters in a column of their own
    failures = pd.read_csv(tmp_path / "report" / "tables" / "failures.csv")
    assert failures.lost.sum() == fake_results(tmp_path).failure.eq("lost").sum()  # counted, not dropped


def test_stats_cli_json(tmp_path, shared_data, capsys):
    assert main(["stats", str(shared_data / "stats_golden" / "observations.csv"), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert list(out["datasets"]) == ["all"]  # a table without a dataset column: one block
    out = out["datasets"]["all"]
    ref = json.loads((shared_data / "stats_golden" / "r_reference.json").read_text())
    assert set(out) == set(ref) | {
        "outlier_note",
        "counted",
        "counting_note",
        "coverage",
        "outlier_tests",
        "marks",
    }  # R's figures, how runs were counted and tested for outliers, the methods' marks
    assert set(out["metrics"]) == set(ref["metrics"]) and out["counted"] == {} and out["outlier_note"] is None
    assert out["n_outliers"] == ref["n_outliers"]
    assert set(out["metrics"]["e_t"]) >= set(ref["metrics"]["e_t"])


CHROMIUM_FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
)


def chromium_or_skip() -> str:
    """The Chromium executable, or a skip saying how to get one."""
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        pytest.skip(reason="Chromium not installed (apt-get install chromium); .ci/run installs it")
    return chromium


def render_in_chromium(index, tmp_path):
    """Open the report in headless Chromium: every figure must decode and lay out; returns a screenshot."""
    chromium = chromium_or_skip()
    flags = [*CHROMIUM_FLAGS, f"--user-data-dir={tmp_path / 'profile'}"]
    dom = subprocess.run(
        [chromium, *flags, "--virtual-time-budget=5000", "--dump-dom", index.as_uri()],
        capture_output=True,
        text=True,
        timeout=120,
    ).stdout
    n_img = index.read_text().count("<img")
    assert f'data-images-loaded="{n_img}/{n_img}"' in dom  # every figure decoded and laid out
    shot = index.parent / "screenshot.png"
    subprocess.run(
        [chromium, *flags, "--window-size=1200,3000", f"--screenshot={shot}", index.as_uri()],
        capture_output=True,
        timeout=120,
    )
    assert shot.exists() and shot.stat().st_size > 10_000
    if os.environ.get("SLAMRUN_KEEP_SHOT"):  # to look at the rendered report yourself
        shutil.copy(shot, os.environ["SLAMRUN_KEEP_SHOT"])
    return shot


def test_report_renders_in_chromium(tmp_path):
    fake_results(tmp_path).to_csv(tmp_path / "results.csv", index=False)
    render_in_chromium(write_report(tmp_path), tmp_path)


def test_a_campaign_with_ate_and_rpe_has_their_table_and_the_paths(tmp_path, tiny_dataset, drawn):
    """A campaign whose dataset asks for ATE and RPE beside TUM-Mono's metrics: the results carry them, the
    report has their table with letters and, per sequence, each method's best, median and worst path over the
    ground truth (axes labelled with their units, equal aspect, a legend of what is drawn), rendered in a real
    browser."""
    from slamrun.engine.campaign import run_campaign
    from slamrun.engine.spec_file import load_spec
    from tests.conftest import fake_method, write_spec

    datasets = [
        {"name": "s", "path": str(tiny_dataset), "sequences": ["seq_a", "seq_b"], "metrics": ["tum-mono", "ate", "rpe"]}
    ]
    spec = write_spec(
        tmp_path,
        tiny_dataset,
        [
            fake_method(label="steady", extra=["--noise", "0.002"]),
            fake_method(label="shaky", extra=["--noise", "0.02"]),
        ],
        datasets=datasets,
        trials=3,
        report=True,
    )
    res = run_campaign(load_spec(spec), on_event=None)
    df = pd.read_csv(res.results_csv)
    assert df.status.eq("done").all() and df.ate_rmse.notna().all() and df.rpe_t_rmse.notna().all()
    assert df.coverage.eq(1.0).all()  # the fake method gives every frame a pose
    medians = df.groupby("method").ate_rmse.median()
    assert medians["steady"] < medians["shaky"]
    index = write_report(res.results)
    table = pd.read_csv(res.results / "report" / "tables" / "trajectory_metrics.csv")
    assert {"ate_rmse", "rpe_t_rmse", "rpe_r_rmse"} <= set(table.columns)
    assert (res.results / "report" / "figures" / "trajectories_seq_a.png").exists()
    assert {"trajectories_seq_a", "trajectories_seq_b"} <= set(drawn)
    for name in ("trajectories_seq_a", "trajectories_seq_b"):
        d = drawn[name]
        assert not d.overlaps()
        panels = [ax for ax in d.figure.axes if ax.get_visible()]
        assert sorted(ax.get_title() for ax in panels) == ["shaky", "steady"]
        for ax in panels:  # TUM-Mono's ground truth has no unit of its own (arbitrary scale)
            assert re.fullmatch(r"[xyz] \(ground-truth units\)", ax.get_xlabel()), ax.get_xlabel()
            assert re.fullmatch(r"[xyz] \(ground-truth units\)", ax.get_ylabel()), ax.get_ylabel()
            assert ax.get_aspect() == 1.0
        drawn_labels = {line.get_label() for ax in panels for line in ax.get_lines()}
        legend = [t.get_text() for t in d.figure.legends[0].get_texts()]
        assert set(legend) == drawn_labels  # the legend names what the panels draw, nothing else
        assert {"best run", "median run", "worst run", "start (ground truth)"} <= set(legend)
        styles = {
            line.get_label(): (line.get_color(), line.get_linestyle()) for line in d.figure.legends[0].get_lines()
        }
        picks = [styles[f"{which} run"] for which in ("best", "median", "worst")]
        assert len({c for c, _ in picks}) == 3 and len({s for _, s in picks}) == 3  # told apart twice over
    render_in_chromium(index, tmp_path)


def test_a_campaign_without_tum_mono_metrics_reports_its_own(tmp_path):
    """EuRoC, KITTI, TUM RGB-D campaigns have ATE and RPE only: the motion-bias and per-sequence tables and the
    figures use ATE, and no empty TUM-Mono figure is drawn."""
    df = fake_results(tmp_path)
    rng = np.random.default_rng(2)
    done = df.status == "done"
    df = df.drop(columns=[c for c in df.columns if c.startswith("e_")])
    df.loc[done, "ate_rmse"] = rng.uniform(0.01, 0.1, int(done.sum()))
    df.loc[done, "rpe_t_rmse"] = rng.uniform(0.001, 0.01, int(done.sum()))
    df.to_csv(tmp_path / "results.csv", index=False)
    write_report(tmp_path)
    tables, figs = tmp_path / "report" / "tables", tmp_path / "report" / "figures"
    bias = pd.read_csv(tables / "motion_bias.csv")
    assert {"median ate_rmse forward", "median ate_rmse backward"} <= set(bias.columns)
    assert (tables / "ate_rmse_per_sequence.csv").exists()
    assert (figs / "cumulative_ate_rmse.png").exists() and (figs / "heatmap_ate_rmse.png").exists()
    assert not list(figs.glob("cumulative_e_*.png"))


# ---------------------------------------------------------------- the figures themselves


@dataclass
class Drawn:
    """A figure as the report drew it, and every text it rendered: (the Text, its extent in display pixels)."""

    figure: object
    texts: list[tuple[object, object]]
    pixels: np.ndarray  # the canvas as drawn, RGBA rows from the top

    def overlaps(self) -> list[tuple[str, str]]:
        """The pairs of rendered texts whose boxes intersect (by more than half a pixel each way)."""
        out = []
        for (a, ea), (b, eb) in itertools.combinations(self.texts, 2):
            if ea.x0 < eb.x1 - 0.5 and eb.x0 < ea.x1 - 0.5 and ea.y0 < eb.y1 - 0.5 and eb.y0 < ea.y1 - 0.5:
                out.append((a.get_text(), b.get_text()))
        return out

    def labels(self, axis) -> list[str]:
        """The tick labels of `axis` that were rendered (major and minor), in order."""
        mine = {id(t.label1) for t in axis.get_major_ticks() + axis.get_minor_ticks()}
        mine |= {id(t.label2) for t in axis.get_major_ticks() + axis.get_minor_ticks()}
        return [t.get_text() for t, _ in self.texts if id(t) in mine]


def drawn_figure(fig) -> Drawn:
    """`fig` drawn: every text matplotlib renders, with its rendered extent (Text.draw observed while the canvas
    draws: tick labels outside the view, empty and hidden texts are not drawn, so not counted), and its pixels."""
    from matplotlib.text import Text

    seen, draw = [], Text.draw

    def observed(self, renderer):
        draw(self, renderer)
        if self.get_visible() and self.get_text().strip() and self not in seen:
            seen.append(self)

    Text.draw = observed
    try:
        fig.canvas.draw()
    finally:
        Text.draw = draw
    renderer = fig.canvas.get_renderer()
    texts = [(t, t.get_window_extent(renderer)) for t in seen]
    return Drawn(fig, texts, np.asarray(fig.canvas.buffer_rgba()).copy())


@contextlib.contextmanager
def figures_drawn():
    """Every figure the report saves meanwhile (by file name), drawn and measured just before it is saved."""
    out: dict[str, Drawn] = {}
    save = figures.save

    def measured(fig, folder, name):
        out[name] = drawn_figure(fig)
        return save(fig, folder, name)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(figures, "save", measured)
        yield out


@pytest.fixture
def drawn():
    with figures_drawn() as out:
        yield out


@pytest.fixture(scope="module")
def report_figures(tmp_path_factory) -> dict[str, Drawn]:
    """The figures of one report of fake_results with ATE and RPE (TUM-Mono's metrics beside them)."""
    folder = tmp_path_factory.mktemp("figures")
    with_trajectory_metrics(fake_results(folder)).to_csv(folder / "results.csv", index=False)
    with figures_drawn() as out:
        write_report(folder)
    return out


def with_trajectory_metrics(df: pd.DataFrame) -> pd.DataFrame:
    """fake_results with ATE and RPE beside TUM-Mono's metrics, spread over about two decades."""
    rng = np.random.default_rng(3)
    done = df.status == "done"
    scale = 1 + df.method.str[1:].astype(int)
    df.loc[done, "ate_rmse"] = rng.lognormal(np.log(0.02 * scale[done]), 0.8)
    df.loc[done, "rpe_t_rmse"] = rng.lognormal(np.log(0.002 * scale[done]), 0.3)
    return df


def test_no_text_of_any_figure_overlaps_another(report_figures):
    assert {"box_e_t", "box_ate_rmse", "cumulative_e_r", "heatmap_e_align"} <= set(report_figures)
    overlapping = {name: d.overlaps() for name, d in report_figures.items() if d.overlaps()}
    assert not overlapping


def test_the_cumulative_figures_label_at_least_three_ticks(report_figures):
    """e_r's runs span about a decade and a half, e_s' less than one: each axis still has three labelled values."""
    cumulative = {name: d for name, d in report_figures.items() if name.startswith("cumulative_")}
    assert len(cumulative) == 8
    for name, d in cumulative.items():
        ax = d.figure.axes[0]
        labels = d.labels(ax.xaxis)
        assert len(labels) >= 3, (name, ax.get_xscale(), labels)


def test_the_heatmap_draws_unplanned_runs_apart_from_failed_and_missing_ones(tmp_path, drawn):
    """Method `once` was planned for one trial forward only: its other cells are no run at all, drawn unlike a
    failed run and unlike a run without a value; each column says its direction and trial."""
    rows = []
    for method, trials, directions in (("many", 3, ("forward", "backward")), ("once", 1, ("forward",))):
        for d in directions:
            for t in range(trials):
                rows.append({"method": method, "sequence": "s1", "direction": d, "trial": t, "status": "done"})
    df = pd.DataFrame(rows)
    df["eval_status"], df["failure"], df["e_align"] = "ok", None, 0.1 + 0.01 * np.arange(len(df))
    df.loc[1, ["status", "failure", "eval_status", "e_align"]] = ["failed", "lost", None, np.nan]  # many f1
    df.loc[2, ["eval_status", "e_align"]] = ["bad_trajectory", np.nan]  # many f2: done, no value
    figures.heatmap(df, tmp_path, "e_align")
    d = drawn["heatmap_e_align"]
    ax = d.figure.axes[0]
    columns = d.labels(ax.xaxis)
    assert columns == ["f0", "f1", "f2", "b0", "b1", "b2"]
    assert any("forward" in t.get_text() and "trial" in t.get_text() for t, _ in d.texts)  # the columns explained

    def colour(method: str, column: str) -> np.ndarray:
        """The mean rendered colour of the middle of a cell (a hatched cell: its background and hatching)."""
        row, col = ["many", "once"].index(method), columns.index(column)
        (x0, y0), (x1, y1) = ax.transData.transform([(col - 0.3, row + 0.3), (col + 0.3, row - 0.3)])
        h = d.pixels.shape[0]
        return d.pixels[h - int(y1) : h - int(y0), int(x0) : int(x1), :3].reshape(-1, 3).mean(axis=0)

    kinds = {"value": ("many", "f0"), "failed": ("many", "f1"), "no value": ("many", "f2"), "unplanned": ("once", "f1")}
    seen = {kind: colour(*cell) for kind, cell in kinds.items()}
    for a, b in itertools.combinations(seen, 2):
        assert np.abs(seen[a] - seen[b]).max() > 25, (a, b, seen)  # told apart
    for cell in (("once", "b0"), ("once", "b2"), ("once", "f2")):
        assert np.abs(colour(*cell) - seen["unplanned"]).max() < 10  # every unplanned cell alike
    legend = " ".join(t.get_text() for t, _ in d.texts)
    assert "not planned" in legend and "failed" in legend


def test_a_new_report_leaves_no_file_of_the_last_one(tmp_path):
    """Reported once with TUM-Mono's metrics (drift tables per direction), then the same runs with ATE and RPE
    only: no table3_drift file stays to claim it holds drift, and a file of the user's own is left alone."""
    df = fake_results(tmp_path)
    df.to_csv(tmp_path / "results.csv", index=False)
    write_report(tmp_path)
    tables = tmp_path / "report" / "tables"
    assert (tables / "table3_drift_forward.csv").is_file()
    (tables / "notes.txt").write_text("mine\n")
    rng = np.random.default_rng(4)
    done = df.status == "done"
    df = df.drop(columns=[c for c in df.columns if c.startswith("e_")])
    df.loc[done, "ate_rmse"] = rng.uniform(0.01, 0.1, int(done.sum()))
    df.to_csv(tmp_path / "results.csv", index=False)
    write_report(tmp_path)
    assert not list(tables.glob("table3_*")) and not list(tables.glob("table4_*"))
    assert (tables / "trajectory_metrics_forward.csv").is_file() and (tables / "notes.txt").read_text() == "mine\n"
    assert not list((tmp_path / "report" / "figures").glob("*e_t*"))


@pytest.mark.parametrize(
    "images, why",
    [
        ("not json", "unreadable"),
        ("[" * 200_000, "unreadable"),  # nested past Python's recursion limit
        ('["a list"]', "expected an object of run labels"),
        ("fifo", "a FIFO"),
        ("x" * (5 << 20), "unreadable"),  # over the size cap
    ],
)
def test_a_bad_image_description_is_named_on_the_page_and_the_report_is_written(tmp_path, images, why):
    fake_results(tmp_path, n_methods=2, n_seq=1, trials=3).to_csv(tmp_path / "results.csv", index=False)
    path = tmp_path / "images.json"
    if images == "fifo":
        os.mkfifo(path)  # never read: a FIFO would block a reader
    else:
        path.write_text(images)
    (tmp_path / "spec.resolved.yaml").write_text("name: [unclosed\n")
    text = write_report(tmp_path).read_text()
    block = text.split("<h3>Images</h3>")[1].split("</p>")[0]
    assert str(path) in block and why in block
    assert "<pre>name: [unclosed\n</pre>" in text and "not a readable spec" in text  # shown as it is


def test_cumulative_figures_keep_their_legend_off_the_curves_and_count_in_whole_runs(report_figures):
    """The legend stood over the data (lower right, where the curves end) and the counts read 1.0, 1.5, 2.0: the
    legend is beside the axes, and the y axis labels whole numbers only."""
    cumulative = {k: d for k, d in report_figures.items() if k.startswith("cumulative_")}
    assert cumulative
    for name, d in cumulative.items():
        ax = d.figure.axes[0]
        assert ax.get_legend() is None and d.figure.legends, name
        entries = {id(t) for t in d.figure.legends[0].get_texts()}
        drawn_entries = [extent for t, extent in d.texts if id(t) in entries]
        assert drawn_entries and all(e.x0 >= ax.bbox.x1 for e in drawn_entries), name  # beside the axes
        labels = d.labels(ax.yaxis)
        assert labels and all(re.fullmatch(r"\d+", t) for t in labels), (name, labels)


def test_the_heatmap_colour_scale_does_not_stretch_a_small_range(drawn, tmp_path):
    """Two methods 6 % apart (0.0282 and 0.0300) were drawn as the colour scale's two ends: the linear scale starts
    at zero, so their colours are close; values a decade apart or more keep the log scale from least to greatest."""
    from matplotlib.colors import LogNorm

    rows = [
        {"method": m, "sequence": "s1", "direction": "forward", "trial": t, "status": "done", "e_align": v}
        for m, v in (("a", 0.0282), ("b", 0.0300))
        for t in range(2)
    ]
    df = pd.DataFrame(rows).assign(failure=None, eval_status="ok")
    figures.heatmap(df, tmp_path, "e_align")
    image = drawn["heatmap_e_align"].figure.axes[0].images[0]
    assert image.norm.vmin == 0 and image.norm.vmax == pytest.approx(0.0300)
    a, b = (np.asarray(image.cmap(image.norm(v))[:3]) for v in (0.0282, 0.0300))
    assert np.abs(a - b).max() < 0.15  # neighbours on the scale, not its two ends
    wide = figures.colour_norm(np.array([0.001, 0.05]))
    assert isinstance(wide, LogNorm) and (wide.vmin, wide.vmax) == (0.001, 0.05)
