// slamrun serve: the live page. Plain DOM, no framework, no network beyond this server.
// Every text from the server is set as text (never as HTML).
"use strict";

const $ = (tag, attrs = {}, ...children) => {
  const el = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (k === "text") el.textContent = v;
    else if (k.startsWith("on")) el.addEventListener(k.slice(2), v);
    else el.setAttribute(k, v);
  }
  for (const c of children) if (c != null) el.append(c);
  return el;
};

function duration(s) {
  if (s == null) return "?";
  s = Math.round(s);
  if (s >= 3600) return `${Math.floor(s / 3600)} h ${String(Math.floor((s % 3600) / 60)).padStart(2, "0")} min`;
  if (s >= 60) return `${Math.floor(s / 60)} min ${String(s % 60).padStart(2, "0")} s`;
  return `${s} s`;
}

const num = (v) => (v == null ? "–" : Math.abs(v) >= 1000 || Math.abs(v) < 0.001 ? v.toExponential(3) : v.toPrecision(4));

function table(headers, rows, cls = "") {
  return $(
    "table",
    { class: cls },
    $("thead", {}, $("tr", {}, ...headers.map((h) => $("th", { text: h })))),
    $("tbody", {}, ...rows.map((r) => $("tr", {}, ...r.map((c) => (c instanceof Node ? $("td", {}, c) : $("td", { text: String(c) })))))),
  );
}

function section(id, title, ...children) {
  return $("section", { id }, $("h2", { text: title }), ...children);
}

// ---------------------------------------------------------------- one campaign
const base = () => `/c/${encodeURIComponent(document.body.dataset.campaign)}/`;

function header(s) {
  const p = s.progress;
  const state = s.state;
  const bar = $("div", { class: "bar" }, $("div", { class: "done", style: `width:${(100 * p.done) / (p.total || 1)}%` }),
    $("div", { class: "failed", style: `width:${(100 * (p.failed + p.infra)) / (p.total || 1)}%` }));
  const facts = s.facts;  // written by the server (the same line its first render of the page shows)
  return $(
    "header",
    { id: "progress", "data-state": state, "data-finished": p.finished, "data-total": p.total, "data-done": p.done },
    $("h1", {}, `${s.campaign} `, $("span", { class: `state ${state}`, text: state })),
    bar,
    $("p", { class: "facts", text: facts.join(" · ") }),
    s.report ? $("p", {}, $("a", { href: `${base()}files/${s.report}`, text: "the report (written when the campaign ends)" })) : null,
    $("p", { class: "muted", text: `read ${new Date(s.generated_at * 1000).toLocaleTimeString()}` }),
  );
}

function lanes(s) {
  if (!s.lanes.length) return section("lanes", "Lanes", $("p", { class: "muted", text: "no run is running now" }));
  const rows = s.lanes.map((r) => [r.label, `${r.dataset}/${r.sequence}`, r.direction, r.trial, r.attempts, duration(r.running_s)]);
  return section("lanes", "What each lane runs", table(["method", "sequence", "direction", "trial", "attempt", "running for"], rows));
}

function groups(s) {
  const rows = s.progress.per_group.map((g) => [g.method, g.direction, g.done, g.failed, g.infra, g.running, g.pending,
    g.success_pct == null ? "–" : `${g.success_pct.toFixed(0)} %`]);
  return section("groups", "Per method and direction", table(["method", "direction", "done", "failed", "infra", "running", "pending", "success"], rows));
}

function logButton(key) {
  const pre = $("pre", { class: "log" });
  const details = $("details", {}, $("summary", { text: "log tail" }), pre);
  details.addEventListener("toggle", async () => {
    if (!details.open || pre.dataset.loaded) return;
    const r = await fetch(`${base()}api/log?key=${encodeURIComponent(key)}`);
    pre.textContent = r.ok ? await r.text() : `(no log: ${(await r.text()).trim()})`;
    pre.dataset.loaded = "1";
  });
  return details;
}

function failures(s) {
  const f = s.failed;
  if (!f.total) return section("failures", "Failures", $("p", { class: "muted", text: "no run has failed" }));
  const kinds = Object.entries(f.kinds).map(([k, n]) => `${k} ${n}`).join(" · ");
  const rows = f.runs.map((r) => [r.failure, r.label, `${r.dataset}/${r.sequence}`, r.direction, r.trial, r.message || "", logButton(r.key)]);
  return section(
    "failures",
    `Failures: ${f.total}`,
    $("p", { text: `by kind: ${kinds}` + (f.total > f.runs.length ? ` (the newest ${f.runs.length} listed)` : "") }),
    $("div", { class: "scroll" }, table(["kind", "method", "sequence", "direction", "trial", "message", ""], rows)),
  );
}

// The box plot's log axis: the ticks the server chose (slamrun/core/ticks.py, the report's rule: 1, 2 and 5 of each
// decade over three decades or less, every tick its whole value, the axis from the tick below the least value to
// the one above the greatest), a little margin so the end labels are not cut.
function logAxis(ticks) {
  if (!ticks || !ticks.length) return {};
  const a = Math.log10(ticks[0]), b = Math.log10(ticks[ticks.length - 1]), pad = 0.02 * (b - a);
  return { tickmode: "array", tickvals: ticks, ticktext: ticks.map(String), autorange: false, range: [a - pad, b + pad] };
}

function medians(s) {
  const out = [];
  for (const [dataset, d] of Object.entries(s.medians)) {
    const rows = d.methods.map((m) => [m.method, m.done, ...d.metrics.map((k) => num(m[k]))]);
    const plot = $("div", { class: "box", id: `box-${dataset}` });
    out.push($("h3", { text: `${dataset || "(no dataset)"}: medians over the done runs so far` }),
      $("div", { class: "scroll" }, table(["method", "done", ...d.metrics.map((k) => s.labels[k] || k)], rows)),
      ...(d.notes || []).map((n) => $("p", { class: "muted", text: n })), plot);
    if (d.main && window.Plotly) {
      // each method in its colour for the whole campaign (the report's figures use the same)
      const traces = Object.entries(d.values).map(([method, vs]) => ({ type: "box", x: vs, name: method, orientation: "h", boxpoints: vs.length < 60 ? "all" : "outliers", marker: { color: s.colours[method] }, line: { color: s.colours[method] } }));
      const ticks = logAxis(d.ticks);
      setTimeout(() => Plotly.react(plot, traces, {  // once the section is in the page (a frame may never come in a hidden tab)
        title: { text: `${s.labels[d.main] || d.main} per method (${dataset}), done runs so far`, font: { size: 13 } },
        xaxis: { type: "log", title: { text: s.labels[d.main] || d.main }, ...ticks }, yaxis: { title: { text: "method" } }, margin: { l: 110, r: 20, t: 40, b: 45 }, height: 90 + 40 * traces.length, showlegend: false,
      }, { displaylogo: false, responsive: true }));
    }
  }
  if (!out.length) out.push($("p", { class: "muted", text: "no run is done yet" }));
  return section("medians", "Medians per dataset", ...out);
}

function figures(s) {
  if (!s.figures.length) return section("figures", "Report figures", $("p", { class: "muted", text: "no report yet: its figures appear here when it is written" }));
  const grid = (list) => $("div", { class: "grid" },
    ...list.map((f) => $("figure", {}, $("a", { href: `${base()}files/${f.path}` },
      $("img", { src: `${base()}files/${f.path}?v=${f.mtime}`, alt: f.name, loading: "lazy" })), $("figcaption", { text: f.name }))));
  const byDataset = new Map();  // the campaign's own figures first, then each dataset's (a multi-dataset report)
  for (const f of s.figures) {
    const key = f.dataset || "";
    if (!byDataset.has(key)) byDataset.set(key, []);
    byDataset.get(key).push(f);
  }
  return section("figures", "Report figures", ...[...byDataset].map(([name, list]) =>
    name ? $("div", { class: "dataset-figures" }, $("h3", { text: `dataset ${name}` }), grid(list)) : grid(list)));
}

// The path viewer keeps its own state across updates (what the user picked).
const viewer = { root: null, plot: null, select: null };

function pathViewer() {
  if (viewer.root) return viewer.root;
  viewer.select = $("select", { id: "run-select", onchange: () => drawPath(viewer.select.value) }, $("option", { value: "", text: "pick a done run" }));
  viewer.plot = $("div", { id: "run-path", class: "path" });
  viewer.note = $("p", { class: "muted" });
  const load = $("button", { text: "list the done runs", onclick: listRuns });
  viewer.root = section("path", "A run's path over the ground truth", $("p", {}, load, " ", viewer.select), viewer.note, viewer.plot);
  return viewer.root;
}

async function listRuns() {
  const r = await fetch(`${base()}api/runs`);
  const d = await r.json();
  viewer.select.replaceChildren($("option", { value: "", text: `pick one of ${d.total} done runs` }),
    ...d.runs.map((run) => $("option", { value: run.key, text: `${run.label} · ${run.dataset}/${run.sequence} · ${run.direction} · trial ${run.trial}` })));
  viewer.note.textContent = d.total > d.runs.length ? `the first ${d.runs.length} of ${d.total} listed` : "";
}

async function drawPath(key) {
  if (!key) return;
  viewer.note.textContent = "reading...";
  const r = await fetch(`${base()}api/path?key=${encodeURIComponent(key)}`);
  if (!r.ok) { viewer.note.textContent = (await r.text()).trim(); return; }
  const fig = await r.json();
  viewer.note.textContent = "";
  Plotly.react(viewer.plot, fig.data, fig.layout, { displaylogo: false, responsive: true });
  viewer.plot.dataset.key = key;
}

// A section is rebuilt only when its part of the snapshot changed: an open log tail stays open, a plot is not redrawn.
const drawn = {};
function part(name, build, input) {
  const key = JSON.stringify(input);
  if (!drawn[name] || drawn[name].key !== key) drawn[name] = { key, node: build() };
  return drawn[name].node;
}

function render(s) {
  const app = document.getElementById("app");
  const p = s.progress;
  app.replaceChildren(
    header(s),
    part("lanes", () => lanes(s), s.lanes.map((l) => [l.key, Math.round((l.running_s || 0) / 5)])),
    part("failures", () => failures(s), s.failed),
    part("medians", () => medians(s), [s.medians, s.colours]),
    part("groups", () => groups(s), p.per_group),
    part("figures", () => figures(s), [s.figures, s.report]),
    pathViewer(),
  );
  document.title = `${s.progress.finished}/${s.progress.total} · ${s.campaign} · slamrun`;
}

const POLL_MS = 5000;

// The page's first state comes with it (rendered by the server, embedded for this script): no request before the
// first render. Then server-sent events while the campaign runs. Once a state says it is not running, the stream
// is closed and opened again every POLL_MS (a stopped campaign may be started again): between two short requests
// nothing is pending, so a headless browser's virtual time runs on and the page settles.
function campaignPage() {
  const first = document.getElementById("first-state");
  if (first) { render(JSON.parse(first.textContent)); first.remove(); }
  follow();
}

function follow() {
  let last = null;
  const source = new EventSource(`${base()}events`);
  source.addEventListener("state", (e) => {
    last = JSON.parse(e.data);
    render(last);
    if (!last.progress.active) { source.close(); setTimeout(follow, POLL_MS); }
  });
  source.addEventListener("problem", (e) => { document.getElementById("app").prepend($("p", { class: "problem", text: JSON.parse(e.data) })); });
  source.onerror = () => {
    // refused (the server streams to 64 viewers at most: 503) or gone for good: the page polls api/state instead
    if (source.readyState === EventSource.CLOSED) { polling(); return; }
    if (last) document.title = `(disconnected) ${last.campaign} · slamrun`;
  };
}

function polling() {
  const note = $("p", { class: "polling", text: `This page polls the campaign every ${POLL_MS / 1000} s: the server streams to as many viewers as it can at once.` });
  const tick = async () => {
    try {
      const r = await fetch(`${base()}api/state`);
      if (r.ok) { render(await r.json()); document.getElementById("app").prepend(note); }
    } catch (err) { /* the server is away: the next tick asks again */ }
    setTimeout(tick, POLL_MS);
  };
  tick();
}

// ---------------------------------------------------------------- a folder of campaigns
async function campaignsPage() {
  const app = document.getElementById("app");
  const draw = async () => {
    const r = await fetch("/api/campaigns");
    const d = await r.json();
    const rows = d.campaigns.map((c) => [$("a", { href: `/c/${encodeURIComponent(c.name)}/`, text: c.name }),
      c.error ? c.error : `${c.finished}/${c.total}`, c.error ? "" : c.active ? "running" : "not running",
      c.error ? "" : `${c.done} done, ${c.failed} failed${c.infra ? `, ${c.infra} infra` : ""}`, c.active ? duration(c.eta_s) : ""]);
    app.replaceChildren($("h1", { text: "Campaigns" }),
      d.campaigns.length ? table(["campaign", "finished", "state", "runs", "ETA"], rows, "campaigns") : $("p", { text: "no campaign here yet" }));
  };
  await draw();
  setInterval(draw, 5000);
}

if (document.body.dataset.view === "campaign") campaignPage();
else campaignsPage();
