"""The report's HTML: a page that fits 1400 px and narrower (tables scroll inside their own box, long words
wrap), every table and figure linked to its files, the provenance block, and the interactive views, loaded from
local files only."""

from __future__ import annotations

import html
import os
import re
import urllib.parse
from pathlib import Path

import pandas as pd

from slamrun.analysis import table_files
from slamrun.analysis.interactive import MAX_POINTS, PLOTLY_JS
from slamrun.analysis.paths import SequencePaths
from slamrun.analysis.provenance import Provenance
from slamrun.results.files import CampaignFiles
from slamrun.results.marks import marked
from slamrun.results.marks import notes as notes_of

VIEW_CLASS = "view"

STYLE = """
body{font-family:sans-serif;max-width:1180px;margin:1.5em auto;padding:0 1em;color:#222;line-height:1.4}
h1{font-size:1.6em}h2{margin-top:2em;border-bottom:1px solid #ddd}h3{margin-top:1.6em}h4{margin-top:1.2em}
p,dd,figcaption,summary,li,.files{overflow-wrap:anywhere}
.table-box{overflow-x:auto;max-width:100%;margin:.4em 0}
table{border-collapse:collapse;font-size:13px}
th{background:#f3f3f3;vertical-align:bottom;max-width:16em}
td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}
td:first-child,th:first-child{text-align:left}
p.caption{font-size:13px;color:#444;margin:.4em 0 .2em;max-width:60em}
p.note{font-size:13px;color:#7a3b00;margin:.2em 0 .4em;max-width:60em}
.files{font-size:12px;color:#555;margin:.2em 0 1em}.files a{margin-right:.6em}
figure{margin:1.5em 0}img{max-width:100%;height:auto}figcaption{font-size:13px}
pre{overflow:auto;max-height:28em;background:#f6f6f6;padding:.6em;font-size:12px}
dl.prov{display:grid;grid-template-columns:minmax(8em,max-content) minmax(0,1fr);gap:.25em 1em}
dl.prov dt{font-weight:bold}dl.prov dd{margin:0}
details.view{margin:1em 0;border:1px solid #ddd;padding:.4em}details.view summary{cursor:pointer}
details.view .plot{width:100%;height:620px}
nav ul{columns:2}
"""

# the views' loader: a view's script is loaded when the view opens (the first of each dataset opens at once); a
# closed view frees its WebGL context
LOADER = """
function slamrunLoad(d){const el=document.getElementById(d.dataset.element);
if(el.dataset.drawn)return;el.dataset.drawn='1';const s=document.createElement('script');
s.src=d.dataset.src;document.body.appendChild(s);}
function slamrunToggle(d){if(d.open){slamrunLoad(d);return;}const el=document.getElementById(d.dataset.element);
if(el.dataset.drawn&&window.Plotly){Plotly.purge(el);delete el.dataset.drawn;}}
document.querySelectorAll('details.view').forEach(d=>{d.addEventListener('toggle',()=>slamrunToggle(d));
if(d.open)slamrunLoad(d);});
"""

# the page says how many of its images decoded (body data-images-loaded="n/n"), for a reader's browser and tests
IMAGES_CHECK = (
    "window.addEventListener('load',()=>{const i=[...document.images];"
    "document.body.dataset.imagesLoaded=i.filter(x=>x.complete&&x.naturalWidth>0).length+'/'+i.length;});"
)

INLINE_SCRIPTS = (LOADER, IMAGES_CHECK)  # the page's only inline scripts: `slamrun serve` allows them by hash


def esc(text: str) -> str:
    return html.escape(str(text))


def href(path: Path, root: Path) -> str:
    """A link from the page in `root` to `path`, relative (the report folder can move; a file beside it, such as
    results.csv, through `..`), URL-quoted."""
    rel = os.path.relpath(Path(path).resolve(), Path(root).resolve())
    return esc(urllib.parse.quote(Path(rel).as_posix()))


def links(files: dict[str, Path], root: Path) -> str:
    """A line of links to files (those that exist)."""
    items = [f'<a href="{href(p, root)}">{esc(name)}</a>' for name, p in files.items() if Path(p).is_file()]
    return f'<p class="files">{" ".join(items)}</p>' if items else ""


def table(
    df: pd.DataFrame,
    folder: Path,
    root: Path,
    name: str,
    title: str,
    caption: str,
    show: bool = True,
    lower_is_better: tuple[str, ...] = (),
    notes: tuple[str, ...] = (),
    marks: dict | None = None,
) -> str:
    """Write a table's CSV, Markdown and LaTeX files, and return its HTML: what its values are, the table in a box
    that scrolls sideways where it is wider than the page, `notes` under it (who it leaves out and why), the links
    to its files (only the links where not `show`). The LaTeX file sets the best value of each column of
    `lower_is_better` in bold. `marks` (results.marks.flags of the section's runs): a marked method's name carries
    its mark, whose meaning is said under the table and in its files' caption; the CSV has them in a column."""
    csv = None
    if marks and "method" in df.columns and (said := mark_notes(marks, df["method"])):
        csv = df.assign(marks=[marks[m].symbol if m in marks else "" for m in df["method"].astype(str)])
        df = df.assign(method=[marked(str(m), marks) for m in df["method"]])
        title, notes = f"{title}. {' '.join(said)}", (*notes, *said)
    table_files.write_all(df, folder, name, title, caption, lower_is_better, csv)
    files = {f"{name}.{ext} ({kind})": folder / f"{name}.{ext}" for ext, kind in _FORMATS}
    if not show:
        return f"<p>{esc(title)}:</p>" + links(files, root)
    cap = f'<p class="caption">{esc(caption)}</p>' if caption else ""
    return f'{cap}<div class="table-box">{table_files.to_html(df)}</div>' + note_lines(notes) + links(files, root)


def mark_notes(marks: dict, shown) -> list[str]:
    """What the marks of the methods `shown` mean ([] where none of them is marked)."""
    names = {str(m) for m in shown}
    return notes_of({m: f for m, f in marks.items() if m in names and f.symbol})


def note_lines(notes) -> str:
    """Lines under a table or figure (who it leaves out and why), those not empty."""
    return "".join(f'<p class="note">{esc(n)}</p>' for n in notes if n)


_FORMATS = (("csv", "CSV"), ("md", "Markdown"), ("tex", "LaTeX"))


def figure(png: Path, root: Path, caption: str, notes: tuple[str, ...] = ()) -> str:
    """A figure: its PNG shown, its caption, `notes` under it (who it leaves out and why), links to its PNG and
    SVG."""
    svg = png.with_suffix(".svg")
    files = links({f"{png.name} (PNG)": png, f"{svg.name} (SVG)": svg}, root)
    return (
        f'<figure><img alt="{esc(caption)}" src="{href(png, root)}" loading="eager">'
        f"<figcaption>{esc(caption)}</figcaption>{note_lines(notes)}{files}</figure>"
    )


def has_view(html_text: str) -> bool:
    """Whether a section's HTML holds an interactive view."""
    return f'<details class="{VIEW_CLASS}"' in html_text


def view(script: Path, root: Path, element: str, sequence: str, paths: SequencePaths, open_: bool) -> str:
    """An interactive view: a details element whose plot is drawn when it opens, from `script`."""
    n = max([len(paths.gt)] + [len(r.positions) for r in paths.runs])
    thin = f" (paths thinned to at most {MAX_POINTS} poses each)" if n > MAX_POINTS else ""
    summary = f"{sequence}: the runs' paths over the ground truth in 3D, interactive{thin}"
    return (
        f'<details class="{VIEW_CLASS}" data-src="{href(script, root)}" data-element="{esc(element)}"'
        f"{' open' if open_ else ''}><summary>{esc(summary)}</summary>"
        f'<div class="plot" id="{esc(element)}"></div></details>'
    )


def provenance_html(p: Provenance, root: Path, results: Path) -> str:
    """The provenance block: campaign, slamrun, backend, host, dates, runs, images, the spec as run."""
    items = [
        ("campaign", esc(p.campaign)),
        ("slamrun", f"version {esc(p.version)}; this report written by commit {esc(p.commit)}"),
        ("runs made by", esc(p.run_commits)),
        ("backend", esc(p.backend)),
        ("runs ran on", esc(p.runs_host)),
        *([("measurement", esc(p.measurement))] if p.measurement else []),
        ("report written on", "<br>".join(f"{esc(k)}: {esc(v)}" for k, v in p.host.items())),
        *((esc(k), esc(v)) for k, v in p.dates.items()),
        *((esc(k), esc(v)) for k, v in p.runs.items()),
    ]
    out = '<dl class="prov">' + "".join(f"<dt>{k}</dt><dd>{v}</dd>" for k, v in items) + "</dl>" + note_lines(p.notes)
    if p.packages:
        out += "<h3>Python packages of the native runs</h3>" + '<dl class="prov">'
        out += "".join(f"<dt>{esc(k)}</dt><dd>{esc(v)}</dd>" for k, v in p.packages.items()) + "</dl>"
    out += "<h3>Images</h3>" + (_images(p.images) if p.images else f"<p>{esc(p.images_note)}</p>")
    out += links({"images.json": results / "images.json"}, root)
    out += "<h3>The spec as run</h3>"
    if p.spec_text is not None:
        out += f"<details><summary>{esc(p.spec_note)}</summary><pre>{esc(p.spec_text)}</pre></details>"
    else:
        out += f"<p>{esc(p.spec_note)}</p>"
    where = CampaignFiles(results)
    files = {p.name: p for p in (where.spec, where.results_csv, where.results_parquet)}
    return out + links(files, root)


IMAGE_KEYS = ("tag", "id", "method", "sources", "vocabulary", "weights", "march")


def _images(images: dict[str, dict[str, str]]) -> str:
    """Per run label its image's labels: the usual ones as columns, any other in the last."""
    rows = []
    for label, labels in images.items():
        row = {"method label": label, **{k: labels.get(k, "-") for k in IMAGE_KEYS}}
        row["other labels"] = "; ".join(f"{k}: {v}" for k, v in labels.items() if k not in IMAGE_KEYS) or "-"
        rows.append(row)
    return f'<div class="table-box">{table_files.to_html(pd.DataFrame(rows))}</div>'


def _anchor(title: str, used: set[str]) -> str:
    base = re.sub(r"[^a-z0-9]+", "-", title.lower()).strip("-") or "section"
    anchor, k = base, 2
    while anchor in used:
        anchor, k = f"{base}-{k}", k + 1
    used.add(anchor)
    return anchor


def _sections(sections, level: int, used: set[str], toc: list[str]) -> str:
    out = []
    for s in sections:
        anchor = _anchor(s.title, used)
        if level == 2:
            toc.append(f'<li><a href="#{anchor}">{esc(s.title)}</a></li>')
        tag = f"h{min(level, 6)}"
        inner = s.html + _sections(s.parts, level + 1, used, toc)
        out.append(f'<section id="{anchor}"><{tag}>{esc(s.title)}</{tag}>{inner}</section>')
    return "".join(out)


def document(title: str, sections, views: bool) -> str:
    """The whole page: contents, then the sections; plotly.js and the views' loader where it has views."""
    toc: list[str] = []
    body = _sections(sections, 2, set(), toc)
    scripts = f'<script src="{PLOTLY_JS}"></script><script>{LOADER}</script>' if views else ""
    return (
        f"<!doctype html><html lang='en'><head><meta charset='utf-8'>"
        f"<meta name='viewport' content='width=device-width, initial-scale=1'><title>{esc(title)} report</title>"
        f"<style>{STYLE}</style><script>{IMAGES_CHECK}</script></head><body><h1>{esc(title)}</h1>"
        f"<nav><ul>{''.join(toc)}</ul></nav>{body}{scripts}</body></html>"
    )
