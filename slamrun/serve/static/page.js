// slamrun serve: the live page. Plain DOM, no framework, no network beyond this server.
// Texts are set as text; the sections are HTML the server rendered, every text escaped there (serve/sections.py).
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
// Its sections come rendered by the server (slamrun/serve/sections.py, every text escaped there) in each state: the
// script places those that changed and adds what needs a browser: the box plots, the log tails, the path viewer.
const base = () => `/c/${encodeURIComponent(document.body.dataset.campaign)}/`;

function wireLogs(node) {
  for (const details of node.querySelectorAll("details.logtail")) {
    const pre = details.querySelector("pre");
    details.addEventListener("toggle", async () => {
      if (!details.open || pre.dataset.loaded) return;
      const r = await fetch(`${base()}api/log?key=${encodeURIComponent(details.dataset.key)}`);
      pre.textContent = r.ok ? await r.text() : `(no log: ${(await r.text()).trim()})`;
      pre.dataset.loaded = "1";
    });
  }
}

// The box plot's log axis: the ticks the server chose (slamrun/core/ticks.py, the report's rule: 1, 2 and 5 of each
// decade over three decades or less, every tick its whole value, the axis from the tick below the least value to
// the one above the greatest), a little margin so the end labels are not cut.
function logAxis(ticks) {
  if (!ticks || !ticks.length) return {};
  const a = Math.log10(ticks[0]), b = Math.log10(ticks[ticks.length - 1]), pad = 0.02 * (b - a);
  return { tickmode: "array", tickvals: ticks, ticktext: ticks.map(String), autorange: false, range: [a - pad, b + pad] };
}

function drawBoxes(s) {
  if (!window.Plotly) return;
  for (const [dataset, d] of Object.entries(s.medians)) {
    const plot = document.getElementById(`box-${dataset}`);
    if (!d.main || !plot) continue;
    // each method in its colour for the whole campaign (the report's figures use the same)
    const traces = Object.entries(d.values).map(([method, vs]) => ({ type: "box", x: vs, name: method, orientation: "h", boxpoints: vs.length < 60 ? "all" : "outliers", marker: { color: s.colours[method] }, line: { color: s.colours[method] } }));
    const ticks = logAxis(d.ticks);
    setTimeout(() => Plotly.react(plot, traces, {  // once the section is in the page (a frame may never come in a hidden tab)
      title: { text: `${s.labels[d.main] || d.main} per method (${dataset}), done runs so far`, font: { size: 13 } },
      xaxis: { type: "log", title: { text: s.labels[d.main] || d.main }, ...ticks }, yaxis: { title: { text: "method" } }, margin: { l: 110, r: 20, t: 40, b: 45 }, height: 90 + 40 * traces.length, showlegend: false,
    }, { displaylogo: false, responsive: true }));
  }
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
    ...d.runs.map((run) => $("option", { value: run.key, text: `${run.method} · ${run.dataset}/${run.sequence} · ${run.direction} · trial ${run.trial}` })));
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

// A section is placed again only when it changed: an open log tail stays open, a plot is not redrawn.
const placed = {};

function place(app, id, html) {
  const t = document.createElement("template");
  t.innerHTML = html;
  const node = t.content.firstElementChild;
  const old = document.getElementById(id);
  if (old) old.replaceWith(node);
  else app.insertBefore(node, viewer.root && viewer.root.isConnected ? viewer.root : null);
  return node;
}

function render(s) {
  const app = document.getElementById("app");
  if (!document.getElementById("progress")) app.replaceChildren();  // a problem said instead of the first state
  app.querySelectorAll(":scope > p.problem").forEach((p) => p.remove());  // a newer state: the problem passed
  for (const [id, html] of Object.entries(s.sections)) {
    const key = id === "medians" ? html + JSON.stringify([s.medians, s.colours]) : html;
    if (placed[id] === key && document.getElementById(id)) continue;
    const node = place(app, id, html);
    placed[id] = key;
    if (id === "failures") wireLogs(node);
    if (id === "medians") drawBoxes(s);
  }
  if (!viewer.root || !viewer.root.isConnected) app.append(pathViewer());
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
      if (r.ok) { render(await r.json()); if (!note.isConnected) document.getElementById("app").prepend(note); }
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
