"""The scope's page: HTML and a small script that draws the series on canvases (no library, no internet)."""

__all__ = ["PAGE"]

PAGE = """<!doctype html>
<html><head><meta charset="utf-8"><title>cogblocks scope</title>
<style>
body { font: 13px sans-serif; margin: 12px; background: #fafafa; }
h1 { font-size: 16px; margin: 0 0 6px 0; }
.panel { margin: 4px 0; }
.panel span { display: block; color: #333; }
canvas { background: #fff; border: 1px solid #ccc; }
#bar { margin: 6px 0; }
#slider { width: 900px; }
</style></head>
<body>
<h1 id="title">cogblocks scope</h1>
<div id="bar"><span id="status">waiting for data</span>
<div id="view" style="display:none">time <input id="slider" type="range" min="0" max="1" step="0.01" value="1">
<span id="at"></span></div></div>
<div id="panels"></div>
<script>
"use strict";
const SPAN = 10.0, KEEP = 6000, W = 900, H = 110;
const COLORS = ["#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf"];
const FIXED = {theta: [0, 2 * Math.PI], theta_l2: [0, 2 * Math.PI], theta_l0: [0, 2 * Math.PI],
               theta_l2_minus_l0: [-Math.PI, Math.PI], r: [0, 1]};
const data = {t: []};
let meta = null, dirty = false, end = null;
window.scope = {ticks: 0, draws: 0, messages: 0, window: null};

function append(msg) {
  for (const key of Object.keys(msg)) {
    if (key === "ticks") continue;
    if (!(key in data)) data[key] = [];
    const arr = data[key];
    for (const v of msg[key]) arr.push(v);
    if (meta.mode === "live" && arr.length > KEEP) arr.splice(0, arr.length - KEEP);
  }
  window.scope.ticks = msg.ticks;
  window.scope.messages += 1;
  dirty = true;
}

function range(series, i0, i1) {
  let lo = Infinity, hi = -Infinity;
  for (const name of series) {
    if (name in FIXED) { lo = Math.min(lo, FIXED[name][0]); hi = Math.max(hi, FIXED[name][1]); continue; }
    const rows = data[name] || [];
    for (let i = i0; i < i1; i++) {
      for (const v of rows[i]) if (v !== null) { lo = Math.min(lo, v); hi = Math.max(hi, v); }
    }
  }
  if (!isFinite(lo)) return [0, 1];
  if (hi - lo < 1e-9) { lo -= 0.5; hi += 0.5; }
  const pad = 0.05 * (hi - lo);
  return [lo - pad, hi + pad];
}

function draw() {
  requestAnimationFrame(draw);
  if (!dirty || !meta || data.t.length === 0) return;
  dirty = false;
  const t = data.t, last = meta.mode === "live" ? t[t.length - 1] : end;
  const first = last - SPAN;
  let i0 = 0; while (i0 < t.length && t[i0] < first) i0++;
  let i1 = i0; while (i1 < t.length && t[i1] <= last) i1++;
  meta.panels.forEach((panel, p) => {
    const canvas = document.getElementById("c" + p), g = canvas.getContext("2d");
    g.clearRect(0, 0, W, H);
    const [lo, hi] = range(panel.series, i0, i1);
    const x = s => (s - first) / SPAN * W, y = v => H - (v - lo) / (hi - lo) * H;
    g.strokeStyle = "#eee"; g.beginPath(); g.moveTo(0, y(0)); g.lineTo(W, y(0)); g.stroke();
    let color = 0;
    for (const name of panel.series) {
      const rows = data[name] || [];
      const channels = i1 > i0 && rows[i0] ? rows[i0].length : 0;
      for (let c = 0; c < channels; c++) {
        g.strokeStyle = COLORS[color++ % COLORS.length]; g.beginPath();
        let pen = false;
        for (let i = i0; i < i1; i++) {
          const v = rows[i][c];
          if (v === null) { pen = false; continue; }
          if (pen) g.lineTo(x(t[i]), y(v)); else g.moveTo(x(t[i]), y(v));
          pen = true;
        }
        g.stroke();
      }
    }
    g.fillStyle = "#555"; g.fillText(hi.toPrecision(3), 2, 10); g.fillText(lo.toPrecision(3), 2, H - 2);
  });
  const late = data.late && data.late.length ? data.late[i1 - 1][0] : 0;
  document.getElementById("status").textContent =
    `ticks ${window.scope.ticks} · t ${last.toFixed(2)} s · late ticks ${late}`;
  window.scope.window = [first, last];
  window.scope.draws += 1;
}

async function start() {
  meta = await (await fetch("/meta")).json();
  document.getElementById("title").textContent = meta.title;
  const holder = document.getElementById("panels");
  meta.panels.forEach((panel, p) => {
    const div = document.createElement("div"); div.className = "panel";
    const label = document.createElement("span"); label.textContent = panel.title + ": " + panel.series.join(", ");
    const canvas = document.createElement("canvas"); canvas.id = "c" + p; canvas.width = W; canvas.height = H;
    div.appendChild(label); div.appendChild(canvas); holder.appendChild(div);
  });
  if (meta.mode === "live") {
    const events = new EventSource("/events");
    events.onmessage = e => append(JSON.parse(e.data));
  } else {
    append(await (await fetch("/data")).json());
    const t = data.t, slider = document.getElementById("slider");
    document.getElementById("view").style.display = "block";
    slider.min = t[0]; slider.max = t[t.length - 1]; slider.value = Math.min(t[0] + SPAN, t[t.length - 1]);
    const move = () => { end = parseFloat(slider.value); document.getElementById("at").textContent =
      `${end.toFixed(2)} s`; dirty = true; };
    slider.addEventListener("input", move); move();
  }
  requestAnimationFrame(draw);
}
start();
</script></body></html>
"""
