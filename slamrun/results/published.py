"""Published figures: what a method's authors report for a sequence, with the protocol they used, printed beside a
campaign's own medians (the report, `slamrun stats`) and never mixed into its tests.

Built in: the files a method folder keeps in `published/` with a `manifest.yaml` saying whose they are and how they
were made (DPVO's and DPV-SLAM's result logs, copied from DPVO's repository): taken from files, never typed. A lab adds
its own as a CSV of the columns of `Published` (README, Published figures), named by the spec's `published:` or
`--published FILE`.
"""

from __future__ import annotations

import csv
import re
import statistics
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from slamrun.errors import SlamRunError
from slamrun.results.catalogue import CATALOGUE, label

METHODS = Path(__file__).resolve().parent.parent / "methods"
ALIGNMENTS = {"sim3": "Sim(3)", "se3": "SE(3)", "none": "no alignment"}
Settings = dict[str, bool | int | float | str]  # a method's parameters by slamrun's names (loop_closure: true)


class Published(BaseModel):
    """One published figure: a method's `metric` on a sequence, over `runs` runs summed up by `statistic`."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    method: str = Field(min_length=1, description="slamrun's name of the method (dpvo)")
    dataset: str = Field(min_length=1, description="the dataset's layout (euroc, tum-rgbd, tartanair, ...)")
    sequence: str = Field(min_length=1, description="the sequence as the source names it (MH_01_easy, desk)")
    metric: str = Field(description="a results column (ate_rmse, rpe_t_rmse, kitti_t_pct, e_align, ...)")
    value: float
    runs: int = Field(ge=1)
    statistic: Literal["median", "mean", "single"]
    alignment: Literal["sim3", "se3", "none"]
    frames: Literal["all", "keyframes"]
    source: str = Field(min_length=1, description="where it is published: repository@commit/file, or paper and table")
    settings: Settings = Field(
        default_factory=dict,
        description="the method's parameters the figure was made with, by slamrun's names (DPV-SLAM's: loop_closure: "
        "true); only a campaign's runs with those parameters are set beside it. In a CSV: `name=value; ...`",
    )

    @field_validator("settings", mode="before")
    @classmethod
    def _pairs(cls, value):
        """A CSV cell `loop_closure=true; stride=2` (YAML values), or nothing."""
        if not isinstance(value, str):
            return value
        pairs = [p.partition("=") for p in value.split(";") if p.strip()]
        if any(not sep or not k.strip() for k, sep, _ in pairs):
            raise ValueError(f"expected name=value pairs separated by ';', got {value!r}")
        return {k.strip(): yaml.safe_load(v.strip()) for k, _, v in pairs}

    def protocol(self) -> str:
        """`published, 5 runs, median ATE RMSE (m), Sim(3), all frames` (and its settings: `, loop_closure=True`)."""
        runs = "1 run" if self.runs == 1 else f"{self.runs} runs"
        frames = "keyframes only" if self.frames == "keyframes" else "all frames"
        settings = "".join(f", {k}={v}" for k, v in self.settings.items())
        how = f"{self.statistic} {label(self.metric)}, {ALIGNMENTS[self.alignment]}"
        return f"published, {runs}, {how}, {frames}{settings}"

    def made_with(self, params: dict | None) -> bool:
        """Whether a campaign's method ran with this figure's settings (its params with their defaults; None where
        they are not known, which only a figure without settings accepts)."""
        if not self.settings:
            return True
        return params is not None and all(params.get(k) == v for k, v in self.settings.items())


COLUMNS = tuple(Published.model_fields)


def read_table(path: Path) -> list[Published]:
    """A lab's reference file: a CSV with a header of COLUMNS. SlamRunError names the file, row and field."""
    try:
        with open(path, newline="") as fh:
            rows = list(csv.DictReader(fh))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise SlamRunError(f"{path}: published figures: not readable ({exc})") from None
    out = []
    for i, row in enumerate(rows, start=2):
        try:
            figure = Published(**{k: (v.strip() if isinstance(v, str) else v) for k, v in row.items()})
        except (ValidationError, TypeError) as exc:
            first = exc.errors()[0] if isinstance(exc, ValidationError) else {"loc": ("?",), "msg": str(exc)}
            where = ".".join(str(x) for x in first["loc"])
            raise SlamRunError(
                f"{path}, line {i}: {where}: {first['msg']} (columns: {', '.join(COLUMNS)}; README, Published figures)"
            ) from None
        if figure.metric not in CATALOGUE:
            raise SlamRunError(f"{path}, line {i}: metric {figure.metric!r} is no results column (e.g. ate_rmse)")
        out.append(figure)
    return out


_HEADER = re.compile(r"^###\s*(\d+) runs per sequence")
_RUNS = re.compile(r"^(\S+)\s+\[(.*)\]\s*$")
_ONE = re.compile(r"^(\S+)\s+([-+0-9.eE]+)\s*$")


def read_dpvo_log(text: str, *, method: str, dataset: str, source: str, **protocol) -> list[Published]:
    """A DPVO result log: each sequence's runs (`name [r1, ..., rN]`), the median of which is the figure; the log's
    own median line (`name value`) must agree (a log whose lines disagree is refused)."""
    header = _HEADER.match(text.lstrip())
    if header is None:
        raise SlamRunError(f"{source}: not a DPVO result log (no '### N runs per sequence' header)")
    runs, stated = {}, {}
    for line in text.splitlines():
        if m := _RUNS.match(line.strip()):
            runs[m.group(1)] = [float(v) for v in m.group(2).split(",")]
        elif (m := _ONE.match(line.strip())) and not line.startswith("AVG"):
            stated[m.group(1)] = float(m.group(2))
    out = []
    for name, values in runs.items():
        median = statistics.median(values)
        if name in stated and abs(stated[name] - median) > 1e-12 * max(1.0, abs(median)):
            raise SlamRunError(f"{source}: {name}: the log states {stated[name]} where its runs' median is {median}")
        out.append(
            Published(method=method, dataset=dataset, sequence=name, value=median, runs=len(values), source=source,
                      **protocol)
        )  # fmt: skip
    return out


class _Log(BaseModel):
    model_config = ConfigDict(extra="forbid")
    file: str
    method: str
    dataset: str
    settings: Settings = {}


class _Manifest(BaseModel):
    model_config = ConfigDict(extra="forbid")
    source: str
    metric: str
    statistic: Literal["median", "mean", "single"]
    alignment: Literal["sim3", "se3", "none"]
    frames: Literal["all", "keyframes"]
    logs: list[_Log]


def built_in() -> list[Published]:
    """Every method folder's published figures (`<method>/published/manifest.yaml` and the logs it lists)."""
    out = []
    for manifest in sorted(METHODS.glob("*/published/manifest.yaml")):
        m = _Manifest(**yaml.safe_load(manifest.read_text()))
        protocol = {"metric": m.metric, "statistic": m.statistic, "alignment": m.alignment, "frames": m.frames}
        for log in m.logs:
            text = (manifest.parent / log.file).read_text()
            out += read_dpvo_log(text, method=log.method, dataset=log.dataset, source=f"{m.source}/logs/{log.file}",
                                 settings=log.settings, **protocol)  # fmt: skip
    return out


def same_sequence(campaign: str, published: str) -> bool:
    """Whether a campaign's sequence is the published one: the same name, or one naming the other's with a prefix
    or suffix (rgbd_dataset_freiburg1_desk and desk; MH_01 and MH_01_easy), case aside."""
    a, b = campaign.lower(), published.lower()
    return a == b or a.endswith("_" + b) or b.endswith("_" + a) or b.startswith(a + "_") or a.startswith(b + "_")


@dataclass(frozen=True)
class Beside:
    """A campaign's median beside a published figure of the same method, sequence and metric."""

    method: str
    sequence: str
    metric: str
    median: float
    n: int
    alignment: str  # the campaign's
    published: Published

    def row(self) -> dict:
        p = self.published
        here = ALIGNMENTS.get(self.alignment, self.alignment)
        differs = [] if self.alignment == p.alignment else [f"aligned by {here} here"]
        return {
            "method": self.method,
            "sequence": self.sequence,
            "metric": self.metric,
            "this campaign, median": self.median,
            "runs": self.n,
            "published": p.value,
            "published as": p.protocol() + (f" ({p.sequence})" if p.sequence != self.sequence else ""),
            "protocol differs": "; ".join(differs) or "-",
            "source": p.source,
        }


FIELDS = [f.name for f in fields(Beside)]
