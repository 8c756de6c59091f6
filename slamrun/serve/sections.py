"""The live page's sections as HTML, rendered once, by the server, from the snapshot: the page's first state (what
curl, a text browser and a screenshot taken at the page's load see) and every later one, sent in the snapshot over
the event stream. The page's script only places them, and keeps what needs a browser: the box plots (from the
snapshot's values), the log tails (read when opened) and the path viewer. Every text from the ledger is escaped."""

from __future__ import annotations

import html
import re
import time
import urllib.parse

from slamrun.engine.progress import duration

SECTIONS = ("progress", "lanes", "failures", "medians", "groups", "figures")  # their ids, in the page's order


def sections(snap: dict) -> dict[str, str]:
    """The campaign page's sections for `snap`, by id: header, lanes, failures, medians, groups, figures."""
    parts = (_header, _lanes, _failures, _medians, _groups, _figures)
    return dict(zip(SECTIONS, (part(snap) for part in parts), strict=True))


def campaign_body(snap: dict) -> str:
    """The sections of the campaign page, in order."""
    return "".join(sections(snap).values())


def embedded(state_json: bytes) -> str:
    """The snapshot (JSON bytes) as a data block the page's script reads: `<` escaped, so no text in it can end the
    block; the browser never runs it (its type is not a script's)."""
    return (
        '<script type="application/json" id="first-state">' + state_json.decode().replace("<", "\\u003c") + "</script>"
    )


class Html(str):
    """A table cell that is markup this module wrote (every other cell is escaped)."""


def _e(value) -> str:
    return value if isinstance(value, Html) else html.escape(str(value), quote=True)


def number(v) -> str:
    """A metric as the page writes it: 4 significant digits, exponent form under 0.001 and from 1000 (JavaScript's
    toPrecision(4) and toExponential(3))."""
    if v is None:
        return "–"
    if abs(v) >= 1000 or abs(v) < 0.001:
        return re.sub(r"e([+-])0*(\d)", r"e\1\2", f"{v:.3e}")
    return f"{v:#.4g}"


def _table(headers: list[str], rows: list[list[str]], cls: str = "") -> str:
    head = "".join(f"<th>{_e(h)}</th>" for h in headers)
    body = "".join("<tr>" + "".join(f"<td>{_e(c)}</td>" for c in row) + "</tr>" for row in rows)
    klass = f' class="{cls}"' if cls else ""
    return f"<table{klass}><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def _section(id_: str, title: str, inner: str) -> str:
    return f'<section id="{id_}"><h2>{_e(title)}</h2>{inner}</section>'


def _muted(text: str) -> str:
    return f'<p class="muted">{_e(text)}</p>'


def _base(snap: dict) -> str:
    return f"/c/{urllib.parse.quote(snap['name'], safe='')}/"


def _header(snap: dict) -> str:
    p, state = snap["progress"], snap["state"]
    total = p["total"] or 1
    bar = (
        f'<div class="bar"><div class="done" style="width:{100 * p["done"] / total:.3f}%"></div>'
        f'<div class="failed" style="width:{100 * (p["failed"] + p["infra"]) / total:.3f}%"></div></div>'
    )
    report = ""
    if snap["report"]:
        href = _base(snap) + "files/" + urllib.parse.quote(snap["report"])
        report = f'<p><a href="{_e(href)}">the report (written when the campaign ends)</a></p>'
    read = time.strftime("%H:%M:%S", time.localtime(snap["generated_at"]))
    attrs = f'data-state="{state}" data-finished="{p["finished"]}" data-total="{p["total"]}" data-done="{p["done"]}"'
    return (
        f'<header id="progress" {attrs}><h1>{_e(snap["campaign"])} <span class="state {state}">{state}</span></h1>'
        f'{bar}<p class="facts">{_e(" · ".join(snap["facts"]))}</p>{report}{_muted(f"read {read}")}</header>'
    )


def _lanes(snap: dict) -> str:
    if not snap["lanes"]:
        return _section("lanes", "Lanes", _muted("no run is running now"))
    rows = [
        [
            r["method"],
            f"{r['dataset']}/{r['sequence']}",
            r["direction"],
            r["trial"],
            r["attempts"],
            duration(r["running_s"]),
        ]
        for r in snap["lanes"]
    ]
    headers = ["method", "sequence", "direction", "trial", "attempt", "running for"]
    return _section("lanes", "What each lane runs", _table(headers, rows))


def _failures(snap: dict) -> str:
    f = snap["failed"]
    if not f["total"]:
        return _section("failures", "Failures", _muted("no run has failed"))
    kinds = " · ".join(f"{k} {n}" for k, n in f["kinds"].items())
    more = f" (the newest {len(f['runs'])} listed)" if f["total"] > len(f["runs"]) else ""
    rows = [
        [r["failure"], r["method"], f"{r['dataset']}/{r['sequence']}", r["direction"], r["trial"], r["message"] or ""]
        + [_log_tail(r["key"])]
        for r in f["runs"]
    ]
    table = _table(["kind", "method", "sequence", "direction", "trial", "message", ""], rows)
    return _section(
        "failures", f"Failures: {f['total']}", f"<p>{_e(f'by kind: {kinds}{more}')}</p><div class=scroll>{table}</div>"
    )


def _log_tail(key: str) -> Html:
    """A run's log tail, read by the page's script when it is opened."""
    summary = '<summary>log tail</summary><pre class="log"></pre>'
    return Html(f'<details class="logtail" data-key="{_e(key)}">{summary}</details>')


def _medians(snap: dict) -> str:
    parts = []
    labels = snap["labels"]
    for dataset, d in snap["medians"].items():
        rows = [[m["method"], m["done"], *(number(m[k]) for k in d["metrics"])] for m in d["methods"]]
        headers = ["method", "done", *(labels.get(k, k) for k in d["metrics"])]
        said = "".join(_muted(n) for n in d.get("notes", []))
        parts.append(
            f"<h3>{_e(dataset or '(no dataset)')}: medians over the done runs so far</h3>"
            f'<div class=scroll>{_table(headers, rows)}</div>{said}<div class="box" id="box-{_e(dataset)}"></div>'
        )
    return _section("medians", "Medians per dataset", "".join(parts) or _muted("no run is done yet"))


def _groups(snap: dict) -> str:
    rows = [
        [g["method"], g["direction"], g["done"], g["failed"], g["infra"], g["running"], g["pending"]]
        + ["–" if g["success_pct"] is None else f"{g['success_pct']:.0f} %"]
        for g in snap["progress"]["per_group"]
    ]
    headers = ["method", "direction", "done", "failed", "infra", "running", "pending", "success"]
    return _section("groups", "Per method and direction", _table(headers, rows))


def _figures(snap: dict) -> str:
    if not snap["figures"]:
        return _section(
            "figures", "Report figures", _muted("no report yet: its figures appear here when it is written")
        )
    base = _base(snap)
    by_dataset: dict[str, list[dict]] = {}
    for f in snap["figures"]:
        by_dataset.setdefault(f["dataset"] or "", []).append(f)
    parts = []
    for name, figures in by_dataset.items():
        grid = "".join(
            f'<figure><a href="{_e(base + "files/" + urllib.parse.quote(f["path"]))}">'
            f'<img src="{_e(base + "files/" + urllib.parse.quote(f["path"]))}?v={f["mtime"]}" alt="{_e(f["name"])}"'
            f' loading="lazy"></a><figcaption>{_e(f["name"])}</figcaption></figure>'
            for f in figures
        )
        grid = f'<div class="grid">{grid}</div>'
        parts.append(f'<div class="dataset-figures"><h3>dataset {_e(name)}</h3>{grid}</div>' if name else grid)
    return _section("figures", "Report figures", "".join(parts))
