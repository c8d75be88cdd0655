// lookahead monitor page: plain JS and <canvas>, no external resources (works offline).
// Data comes from /api/stream (Server-Sent Events, one "update" per 100 ms); commands go
// to POST /api/cmd/<machine>/<verb>. Chart rows are the monitor's decimated bins: peak
// |v|, |a|, |j| / limit per axis and peak feed over 20 ms of job time.
"use strict";

const AXIS_COLORS = ["#4fc3f7", "#ffa94d", "#9be564", "#e879f9", "#f87171", "#fde047"];
const MAX_ROWS = 3000;
const machines = {};

function el(root, sel) { return root.querySelector(sel); }
function fmt(x, d = 2) { return x === null || x === undefined ? "—" : Number(x).toFixed(d); }
function pct(x) { return x === null || x === undefined ? "—" : (100 * x).toFixed(0) + "%"; }

function makeMachine(spec) {
  const node = document.getElementById("machine-template").content.firstElementChild.cloneNode(true);
  document.getElementById("machines").appendChild(node);
  const m = { spec, node, rows: [], path: null, status: null, snap: null, drawn: 0,
    lastRow: -1, lastEvent: -1 };
  el(node, ".ns").textContent = spec.ns;
  node.dataset.machine = spec.id;
  const ax = el(node, ".ax"), ay = el(node, ".ay");
  spec.axes.forEach((a, i) => {
    ax.add(new Option(a, i)); ay.add(new Option(a, i));
  });
  ax.value = 0; ay.value = spec.axes.length > 1 ? 1 : 0;
  [ax, ay, el(node, ".window")].forEach(s => s.addEventListener("change", () => draw(m)));
  el(node, ".legend").innerHTML = `<span><i style="background:#e6edf3"></i>feed</span>` +
    spec.axes.map((a, i) => `<span><i style="background:${AXIS_COLORS[i % 6]}"></i>${a}</span>`).join("");
  for (const verb of ["hold", "resume", "abort"]) {
    el(node, "." + verb).addEventListener("click", () => command(m, verb));
  }
  const ovr = el(node, ".ovr");
  ovr.addEventListener("input", () => {
    m.ovrTouched = true; el(node, ".ovrval").textContent = Number(ovr.value).toFixed(2);
  });
  el(node, ".setovr").addEventListener("click", () => command(m, "override", Number(ovr.value)));
  machines[spec.id] = m;
  return m;
}

async function command(m, verb, value) {
  const reply = el(m.node, ".reply");
  reply.className = "reply";
  reply.textContent = `${verb}${value === undefined ? "" : " " + value.toFixed(2)}: sending…`;
  try {
    const r = await fetch(`/api/cmd/${encodeURIComponent(m.spec.id)}/${verb}`, {
      method: "POST", headers: { "Content-Type": "application/json" },
      body: JSON.stringify(value === undefined ? {} : { value }) });
    const data = await r.json();
    const what = `${verb}${value === undefined ? "" : " " + value.toFixed(2)}`;
    if (data.ok) {
      reply.className = "reply ok"; reply.textContent = `${what}: accepted by the service`;
    } else {
      reply.className = "reply err";
      reply.textContent = `${what}: refused by the ${data.by || "service"}: ${data.error}`;
    }
  } catch (e) {
    reply.className = "reply err"; reply.textContent = `${verb}: the monitor did not answer (${e})`;
  }
}

function update(m, snap) {
  m.snap = snap;
  const rows = snap.rows.filter(r => r.id > m.lastRow);
  if (rows.length) {
    if (m.rows.length && rows[0].t < m.rows[m.rows.length - 1].t) m.rows = []; // new job
    m.rows.push(...rows);
    m.lastRow = rows[rows.length - 1].id;
    if (m.rows.length > MAX_ROWS) m.rows.splice(0, m.rows.length - MAX_ROWS);
  }
  if (snap.path) m.path = snap.path;
  const n = m.node, st = snap.status;
  n.dataset.service = snap.service;
  const none = el(n, ".noservice");
  if (snap.service === "none") {
    none.hidden = false;
    none.textContent = `No service on ${snap.ns}: no planner liveliness token ` +
      `(${snap.ns}/alive/planner). Start one with \`lookahead serve --machine-id ${snap.id}\`.`;
  } else none.hidden = true;
  const quiet = snap.service === "none" && !m.rows.length;  // nothing to draw: keep it short
  for (const part of [".views", ".controls", ".bottom", ".progress"]) el(n, part).hidden = quiet;
  const stale = st && snap.service === "up" && snap.status_age_s > 1.0;  // >= 5 Hz promised
  const state = snap.service === "none" ? "no service" : st ? st.state + (stale ? " (stale)" : "")
    : "waiting";
  const badge = el(n, ".state");
  badge.textContent = state;
  badge.className = "state badge " + (snap.service === "none" ? "none" : st ? st.state : "");
  n.dataset.state = state;
  el(n, ".job").textContent = snap.job ? "job " + snap.job : "no job";
  el(n, ".winder").textContent = snap.machine_alive ? "machine: consuming setpoints" :
    snap.machine_alive === false ? "machine: none on the bus" : "";
  el(n, ".planner").textContent = st ? st.planner : "—";
  el(n, ".override").textContent = st ? fmt(st.override) : "—";
  if (st && !m.ovrTouched) {  // the slider starts where the service is
    el(n, ".ovr").value = st.override; el(n, ".ovrval").textContent = fmt(st.override);
  }
  const fb = el(n, ".fallbacks");
  fb.textContent = st ? st.fallbacks : "—";
  fb.classList.toggle("bad", !!(st && st.fallbacks));
  el(n, ".planms").textContent = st ? fmt(st.plan_ms, 1) : "—";
  el(n, ".queued").textContent = st ? st.queued : "—";
  const last = m.rows[m.rows.length - 1];
  el(n, ".feed").textContent = last ? fmt(last.feed, 1) : "—";
  el(n, ".peaks").textContent = m.spec.axes.map((a, i) =>
    `${a} ${pct(snap.peak.v[i])} / ${pct(snap.peak.a[i])} / ${pct(snap.peak.j[i])}`).join("   ");
  drawProgress(m, snap.progress, snap.backlog);
  const events = snap.events.filter(e => e.id > m.lastEvent);
  if (events.length) {
    addEvents(m, events);
    m.lastEvent = events[events.length - 1].id;
  }
  if (snap.report) showReport(m, snap.report);
  draw(m);
}

function drawProgress(m, p, backlog) {
  const n = m.node;
  const frac = p.fraction;
  el(n, ".fill").style.width = frac === null ? "0" : (100 * frac).toFixed(1) + "%";
  el(n, ".pct").textContent = frac === null ? "progress unknown" : (100 * frac).toFixed(1) + " %";
  n.dataset.progress = frac === null ? "" : frac;
  const parts = [];
  if (p.elapsed_s !== null) parts.push(`elapsed ${fmt(p.elapsed_s, 1)} s (job time k·dt)`);
  if (p.duration_s !== null && p.duration_s !== undefined)
    parts.push(`job finished: duration ${fmt(p.duration_s, 2)} s`);
  else if (p.remaining_s !== null && p.remaining_s !== undefined)
    parts.push(`time left ${fmt(p.remaining_s, 2)} s (the service's plan reaches the end ` +
      `of the job; motion time at the current override, holds not counted)`);
  else if (p.planned_ahead_s !== null)
    parts.push(`planned ahead ${fmt(p.planned_ahead_s, 2)} s (end not planned yet)`);
  if (p.basis) parts.push("progress: " + p.basis);
  if (backlog > 100) parts.push(`the monitor is catching up: ${backlog} messages queued on its side`);
  el(n, ".ptext").textContent = parts.join(" · ");
}

function addEvents(m, events) {
  const list = el(m.node, ".events");
  for (const e of events) {
    const li = document.createElement("li");
    li.className = e.type;
    const extra = Object.entries(e).filter(([k]) => !["id", "wall", "type", "job", "k"].includes(k))
      .map(([k, v]) => `${k}=${typeof v === "number" ? +v.toFixed(4) : v}`).join(" ");
    const t = new Date(e.wall * 1000).toLocaleTimeString();
    li.innerHTML = `<span class="t">${t}</span>`;
    li.appendChild(document.createTextNode(`${e.type} job=${e.job} k=${e.k} ${extra}`));
    list.insertBefore(li, list.firstChild);
  }
  while (list.children.length > 200) list.removeChild(list.lastChild);
}

function count(x) { return `<td class="${x ? "dirty" : ""}">${x}</td>`; }

function showReport(m, r) {
  const box = el(m.node, ".report");
  const axes = r.axes || m.spec.axes;
  const rows = ["v", "a", "j"].map(k => `<tr><th>peak ${k}</th>` +
    axes.map((a, i) => `<td>${a} ${pct(r.peak_fraction[k][i])}</td>`).join("") + "</tr>").join("");
  const esc = s => String(s).replace(/[&<>]/g, c => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;" })[c]);
  box.innerHTML = `<div>job <b>${esc(r.job)}</b>: <span class="${r.clean ? "clean" : "dirty"}">` +
    `${r.clean ? "CLEAN" : "NOT CLEAN"}</span>, ${fmt(r.duration_s, 3)} s, ${r.samples} samples</div>` +
    `<table>${rows}<tr><th>violations</th>${count(r.violations)}<th>gaps</th>${count(r.gaps)}` +
    `<th>underruns</th>${count(r.underruns)}</tr>` +
    `<tr><th>fibre angle error</th><td colspan="5">max ${fmt(r.fibre_angle_error_max, 4)}° · mean ` +
    `${fmt(r.fibre_angle_error_mean, 4)}° over ${(r.traverses || []).length} traverses</td></tr>` +
    `<tr><th>fallbacks</th><td>${r.fallbacks === null ? "unknown" : r.fallbacks}</td></tr>` +
    (r.fault ? `<tr><th>fault</th><td colspan="5" class="dirty">${esc(r.fault)}</td></tr>` : "") +
    `</table>`;
}

function fitCanvas(c) {
  const dpr = window.devicePixelRatio || 1;
  const w = Math.max(1, Math.round(c.clientWidth * dpr)), h = Math.max(1, Math.round(c.clientHeight * dpr));
  if (c.width !== w || c.height !== h) { c.width = w; c.height = h; }
  const g = c.getContext("2d");
  g.setTransform(dpr, 0, 0, dpr, 0, 0);
  return [g, c.clientWidth, c.clientHeight];
}

function draw(m) {
  m.drawn = drawChart(m) + drawPath(m);
  const c = el(m.node, ".chart").getBoundingClientRect();
  document.body.dataset.chartPoints = Object.values(machines).reduce((s, x) => s + x.drawn, 0);
  if (m === Object.values(machines)[0])
    document.body.dataset.chartRect = [c.left, c.top, c.width, c.height].map(Math.round).join(",");
}

function drawChart(m) {
  const [g, W, H] = fitCanvas(el(m.node, ".chart"));
  g.clearRect(0, 0, W, H);
  const span = Number(el(m.node, ".window").value);
  const rows = m.rows;
  const tEnd = Math.max(rows.length ? rows[rows.length - 1].t : 0, span);
  const t0 = tEnd - span;  // the first `span` seconds fill from the left, then it scrolls
  const left = 46, right = 8, gap = 8, head = 6;
  const panels = [{ key: "feed", label: "feed", unit: "/s" }, { key: "v", label: "|v|/vmax" },
    { key: "a", label: "|a|/amax" }, { key: "j", label: "|j|/jmax" }];
  const ph = (H - 18 - head - gap * (panels.length - 1)) / panels.length;
  const X = t => left + (t - t0) / span * (W - left - right);
  let first = 0;
  while (first < rows.length && rows[first].t < t0) first++;
  const vis = rows.slice(Math.max(first - 1, 0));
  let feedMax = 1;
  for (const r of vis) feedMax = Math.max(feedMax, r.feed);
  feedMax = niceCeil(feedMax * 1.05);
  let points = 0;
  g.font = "11px system-ui, sans-serif";
  panels.forEach((p, pi) => {
    const top = head + pi * (ph + gap);
    const ymax = p.key === "feed" ? feedMax : 1.15;
    const Y = v => top + ph - Math.min(v, ymax) / ymax * ph;
    g.fillStyle = "#0c1116"; g.fillRect(left, top, W - left - right, ph);
    g.strokeStyle = "#222c36"; g.lineWidth = 1;
    const ticks = p.key === "feed" ? [0, feedMax / 2, feedMax] : [0, 0.5, 1];
    g.fillStyle = "#8793a0"; g.textAlign = "right"; g.textBaseline = "middle";
    for (const tk of ticks) {
      g.beginPath(); g.moveTo(left, Y(tk)); g.lineTo(W - right, Y(tk)); g.stroke();
      g.fillText(p.key === "feed" ? String(Math.round(tk)) : (tk * 100) + "%", left - 4, Y(tk));
    }
    g.save(); g.textAlign = "left"; g.textBaseline = "top"; g.fillStyle = "#aab6c2";
    g.fillText(p.key === "feed" ? `feed (path units/s)` : p.label, left + 4, top + 2); g.restore();
    if (p.key !== "feed") {  // the limit
      g.strokeStyle = "#ff5a5f"; g.setLineDash([5, 4]);
      g.beginPath(); g.moveTo(left, Y(1)); g.lineTo(W - right, Y(1)); g.stroke(); g.setLineDash([]);
    }
    g.save(); g.beginPath(); g.rect(left, top, W - left - right, ph); g.clip();
    const series = p.key === "feed" ? [[r => r.feed, "#e6edf3"]] :
      m.spec.axes.map((a, i) => [r => r[p.key][i], AXIS_COLORS[i % 6]]);
    g.lineWidth = 1.6;
    for (const [get, color] of series) {
      g.strokeStyle = color; g.beginPath();
      vis.forEach((r, i) => { const x = X(r.t), y = Y(get(r)); if (i) g.lineTo(x, y); else g.moveTo(x, y); });
      g.stroke(); points += vis.length;
    }
    g.restore();
  });
  g.fillStyle = "#8793a0"; g.textAlign = "center"; g.textBaseline = "bottom";
  const step = span <= 10 ? 2 : span <= 20 ? 5 : 10;
  for (let t = Math.ceil(t0 / step) * step; t <= tEnd + 1e-9; t += step) {
    if (t >= 0) g.fillText(t.toFixed(0) + " s", X(t), H - 2);
  }
  if (!rows.length) {
    g.textAlign = "center"; g.textBaseline = "middle"; g.fillStyle = "#8793a0";
    g.font = "14px system-ui, sans-serif";
    g.fillText("no setpoints yet", W / 2, H / 2);
  }
  return points;
}

function niceCeil(x) {
  const p = Math.pow(10, Math.floor(Math.log10(x)));
  for (const f of [1, 2, 2.5, 5, 10]) if (f * p >= x) return f * p;
  return 10 * p;
}

function drawPath(m) {
  const [g, W, H] = fitCanvas(el(m.node, ".path"));
  g.clearRect(0, 0, W, H);
  g.fillStyle = "#0c1116"; g.fillRect(0, 0, W, H);
  const ix = Number(el(m.node, ".ax").value), iy = Number(el(m.node, ".ay").value);
  const prog = m.path && m.snap && m.path.job === m.snap.job ? m.path.points : [];
  const trail = m.rows.map(r => r.pos);
  const pts = prog.concat(trail);
  if (m.snap && m.snap.position) pts.push(m.snap.position);
  el(m.node, ".pathinfo").textContent = m.path ? `${m.path.segments} segment${m.path.segments === 1 ? "" : "s"}` +
    (m.path.complete ? "" : " (incomplete)") : "no segments seen";
  if (!pts.length) {
    g.fillStyle = "#8793a0"; g.textAlign = "center"; g.font = "14px system-ui, sans-serif";
    g.fillText("no path yet", W / 2, H / 2); return 0;
  }
  let x0 = Infinity, x1 = -Infinity, y0 = Infinity, y1 = -Infinity;
  for (const p of pts) { x0 = Math.min(x0, p[ix]); x1 = Math.max(x1, p[ix]); y0 = Math.min(y0, p[iy]); y1 = Math.max(y1, p[iy]); }
  const pad = 28, dx = (x1 - x0) || 1, dy = (y1 - y0) || 1;
  const X = v => pad + (v - x0) / dx * (W - 2 * pad), Y = v => H - pad - (v - y0) / dy * (H - 2 * pad);
  g.strokeStyle = "#222c36"; g.strokeRect(pad, pad, W - 2 * pad, H - 2 * pad);
  g.fillStyle = "#8793a0"; g.font = "11px system-ui, sans-serif";
  const u = m.spec.units;
  g.textAlign = "left"; g.fillText(`${m.spec.axes[ix]} ${fmt(x0, 0)}`, pad, H - 8);
  g.textAlign = "right"; g.fillText(`${fmt(x1, 0)} ${u[ix]}`, W - pad, H - 8);
  g.textAlign = "left"; g.fillText(`${m.spec.axes[iy]} ${fmt(y1, 0)} ${u[iy]}`, pad, pad - 8);
  g.fillText(`${fmt(y0, 0)}`, 2, H - pad);
  const line = (arr, color, width) => {
    if (arr.length < 2) return;
    g.strokeStyle = color; g.lineWidth = width; g.beginPath();
    arr.forEach((p, i) => { if (i) g.lineTo(X(p[ix]), Y(p[iy])); else g.moveTo(X(p[ix]), Y(p[iy])); });
    g.stroke();
  };
  line(prog, "#56606b", 1.2);
  line(trail, "#4fc3f7", 2);
  const here = m.snap && m.snap.position;
  if (here) {
    g.fillStyle = "#ff5a5f"; g.beginPath(); g.arc(X(here[ix]), Y(here[iy]), 6, 0, 2 * Math.PI); g.fill();
    g.strokeStyle = "#fff"; g.lineWidth = 1.5; g.stroke();
  }
  return prog.length + trail.length;
}

let instance = null;

function hello(h) {
  // the same monitor again (the stream reconnected, or after /api/boot.js): keep the page;
  // the stream re-sends its backlog and `update` skips rows and events already shown
  if (h.instance === instance) return;
  instance = h.instance;
  document.getElementById("machines").innerHTML = "";
  for (const k of Object.keys(machines)) delete machines[k];
  h.machines.forEach(makeMachine);
}

function updateAll(snaps) {
  for (const snap of snaps) if (machines[snap.id]) update(machines[snap.id], snap);
}

function connect() {
  const link = document.getElementById("link");
  const es = new EventSource("/api/stream");
  es.addEventListener("hello", ev => {
    hello(JSON.parse(ev.data));  // the stream re-sends the backlog after it
    link.className = "link up"; link.textContent = "live";
  });
  es.addEventListener("update", ev => updateAll(JSON.parse(ev.data)));
  es.onerror = () => { link.className = "link down"; link.textContent = "monitor connection lost, retrying…"; };
}

window.addEventListener("resize", () => Object.values(machines).forEach(draw));
if (window.MONITOR_BOOT) {  // the first picture, drawn before the page's load event
  hello(window.MONITOR_BOOT.hello);
  updateAll(window.MONITOR_BOOT.update);
}
connect();
