// The telemetry plots (uPlot), their shared timeline, the compared sortie's legend and the
// series they show (fetched for the sortie on screen, appended from each telemetry message).
// A part of the dashboard page (web/app.js lists them); the parts share the page's globals.
"use strict";

// The plots show the whole sortie on screen: a running one as far as it has flown (from
// /api/sortie/series when the page loads, then every telemetry message), a recorded one whole
// (from /api/logs/{name}/series) with a cursor at the replay time. A compared sortie ("B") is
// drawn dashed in colours of its own. All plots share one x range, one cursor and one timeline.
const unitText = (u) => (u === "-" ? "" : u.replace("^2", "²"));
const PLOT_DEFS = [
  { title: "normal acceleration", unit: "m/s²", series: [{ label: "a_n", key: "normal_accel_m_s2", color: "#d7263d" }] },
  { title: "speed and normal velocity", unit: "m/s", series: [{ label: "|v|", key: "speed_m_s", color: "#2f6fe0" }, { label: "v normal to LOS", key: "normal_vel_m_s", color: "#f08a24" }] },
  { title: "image error (DKF)", unit: "px", series: [{ label: "e_x", key: "e_x_px", color: "#19a35b" }, { label: "e_y", key: "e_y_px", color: "#8e44ad" }] },
  { title: "range to target", unit: "m", series: [{ label: "range", key: "range_m", color: "#1d2329" }] },
];
const B_COLORS = ["#00a8a8", "#b8860b", "#e0529c", "#6b8e23"];
const EVENT_COLORS = { detection: "#a8322b", state: "#2f6fe0", gain: "#9a6b00", closest: "#1f7a3a", event: "#5b6670" };

const PV = (W.plotView = {
  own: null, // {t_s: [], columns: {key: []}, fields?: {...}}
  cmp: null, cmpInfo: null, ownInfo: null,
  events: [], tNow: 0, xRange: null, extra: [], hover: false, dirty: true, lastDraw: 0,
});
W.plots = [];
function emptyOwn() { return { t_s: [], columns: Object.fromEntries(PLOT_DEFS.flatMap((d) => d.series.map((s) => [s.key, []]))) }; }
PV.own = emptyOwn();

function plotDefs() { return PLOT_DEFS.concat(PV.extra); }
function tEnd() {
  const a = PV.own.t_s.length ? PV.own.t_s[PV.own.t_s.length - 1] : 0;
  const b = PV.cmp && PV.cmp.t_s.length ? PV.cmp.t_s[PV.cmp.t_s.length - 1] : 0;
  return Math.max(a, b, 1);
}
function currentRange() { return PV.xRange || [0, tEnd()]; }
function setXRange(r) {
  PV.xRange = r;
  const [min, max] = currentRange();
  for (const u of W.plots) if (!u.xy) u.setScale("x", { min, max });
  drawTimeline();
}

function colOf(src, key) {
  if (src.columns && key in src.columns) return src.columns[key];
  if (src.fields && key in src.fields) return src.fields[key];
  return src.t_s.map(() => null);
}
function plotData(def) {
  const own = [PV.own.t_s, ...def.series.map((s) => colOf(PV.own, s.key))];
  if (!PV.cmp) return own;
  const cmp = [PV.cmp.t_s, ...def.series.map((s) => colOf(PV.cmp, s.key))];
  return uPlot.join([own, cmp]);
}

// the legend's value at the cursor: the sample there, else the series' nearest within 0.1 s
// (two sorties are sampled at different times; nothing is interpolated)
function legendVal(u, v, si, idx) {
  if ((v === null || v === undefined) && idx !== null && idx !== undefined) {
    const xs = u.data[0], ys = u.data[si], t = xs[idx];
    for (let d = 1; d < 40; d++) {
      for (const j of [idx - d, idx + d]) if (j >= 0 && j < xs.length && ys[j] !== null && ys[j] !== undefined && Math.abs(xs[j] - t) <= 0.1) return fmtVal(ys[j]);
    }
  }
  return fmtVal(v);
}
const fmtVal = window.fmtNum; // the one rounding rule (web/format.js)

function markerHook(u) {
  const ctx = u.ctx, { top, height } = u.bbox;
  ctx.save();
  for (const [t, kind] of PV.events) {
    if (t === null) continue;
    const x = u.valToPos(t, "x", true);
    if (x < u.bbox.left || x > u.bbox.left + u.bbox.width) continue;
    ctx.strokeStyle = EVENT_COLORS[kind] || "#5b6670"; ctx.setLineDash([3, 3]); ctx.lineWidth = 1;
    ctx.beginPath(); ctx.moveTo(x, top); ctx.lineTo(x, top + height); ctx.stroke();
  }
  const x = u.valToPos(PV.tNow, "x", true);
  ctx.setLineDash([]); ctx.strokeStyle = "#d7263d"; ctx.lineWidth = 2 * devicePixelRatio;
  ctx.beginPath(); ctx.moveTo(x, top); ctx.lineTo(x, top + height); ctx.stroke();
  ctx.restore();
}

// room on the right for the last tick's label (uPlot centres it on the plot's edge)
const PLOT_PADDING = [null, 16, null, null];
function makePlot(def, parent) {
  const series = [{ label: "t (s)", value: (u, v) => fmtVal(v) }];
  def.series.forEach((s) => series.push({ label: PV.cmp ? `${s.label} · A` : s.label, stroke: s.color, width: 1.5, spanGaps: true, value: legendVal }));
  if (PV.cmp) def.series.forEach((s, i) => series.push({ label: `${s.label} · B`, stroke: B_COLORS[(PLOT_DEFS.indexOf(def) + i) % B_COLORS.length], width: 1.5, dash: [6, 4], spanGaps: true, value: legendVal }));
  const box = document.createElement("div"); box.className = "plot"; parent.appendChild(box);
  const width = Math.max(parent.clientWidth / 2 - 10, 300);
  const u = new uPlot({
    title: `${def.title} (${def.unit})`, width, height: 190, series, padding: PLOT_PADDING,
    scales: { x: { time: false, auto: false, range: () => currentRange() } },
    axes: [{ label: "time (s)", labelSize: 16, size: 34 }, { label: def.unit, labelSize: 16, size: 52 }],
    cursor: { sync: { key: "peregrine", setSeries: false }, drag: { x: true, y: false, setScale: false } },
    legend: { live: true },
    hooks: {
      draw: [markerHook],
      setSelect: [(u) => {
        if (u.select.width > 4) setXRange([u.posToVal(u.select.left, "x"), u.posToVal(u.select.left + u.select.width, "x")]);
        u.setSelect({ left: 0, top: 0, width: 0, height: 0 }, false);
      }],
    },
  }, plotData(def), box);
  u.def = def;
  u.over.addEventListener("dblclick", () => setXRange(null));
  u.over.addEventListener("mouseenter", () => { PV.hover = true; });
  u.over.addEventListener("mouseleave", () => { PV.hover = false; PV.dirty = true; });
  u.over.addEventListener("wheel", (ev) => {
    ev.preventDefault();
    const [min, max] = currentRange(), span = max - min;
    if (ev.shiftKey) { const d = (ev.deltaY > 0 ? 0.1 : -0.1) * span; setXRange([min + d, max + d]); return; }
    const at = u.posToVal(ev.offsetX, "x"), k = ev.deltaY > 0 ? 1.25 : 0.8;
    setXRange([at - (at - min) * k, at + (max - at) * k]);
  }, { passive: false });
  return u;
}

function makeXY(parent) {
  const box = document.createElement("div"); box.className = "plot"; parent.appendChild(box);
  const series = [{}, { label: PV.cmp ? "image error · A" : "image error", stroke: "#19a35b", width: 1.5, paths: uPlot.paths.linear(), points: { show: false }, facets: [{ scale: "x", auto: true }, { scale: "y", auto: true }] }];
  if (PV.cmp) series.push({ label: "image error · B", stroke: B_COLORS[0], dash: [6, 4], width: 1.5, paths: uPlot.paths.linear(), points: { show: false }, facets: [{ scale: "x", auto: true }, { scale: "y", auto: true }] });
  const u = new uPlot({
    mode: 2, title: "image error: e_x against e_y (px)", width: Math.max(parent.clientWidth / 2 - 10, 300), height: 190, series, padding: PLOT_PADDING,
    scales: { x: { time: false, range: padRange }, y: { dir: -1, range: padRange } }, legend: { live: false },
    axes: [{ label: "e_x (px)", labelSize: 16, size: 34 }, { label: "e_y (px, down)", labelSize: 16, size: 52 }],
    hooks: { draw: [(u) => { // the point at the cursor time
      const src = PV.own; if (!src.t_s.length) return;
      let i = src.t_s.findIndex((t) => t >= PV.tNow); if (i < 0) i = src.t_s.length - 1;
      const ex = colOf(src, "e_x_px")[i], ey = colOf(src, "e_y_px")[i]; if (ex === null || ey === null) return;
      const x = u.valToPos(ex, "x", true), y = u.valToPos(ey, "y", true);
      u.ctx.save(); u.ctx.strokeStyle = "#d7263d"; u.ctx.lineWidth = 2 * devicePixelRatio;
      u.ctx.beginPath(); u.ctx.arc(x, y, 5 * devicePixelRatio, 0, 2 * Math.PI); u.ctx.stroke(); u.ctx.restore();
    }] },
  }, xyData(), box);
  u.xy = true;
  return u;
}
function padRange(u, min, max) { // never an empty range: a still target is one point
  if (min === null || max === null || !isFinite(min) || !isFinite(max)) return [-1, 1];
  if (max - min < 1e-6) return [min - 1, max + 1];
  const pad = 0.05 * (max - min); return [min - pad, max + pad];
}
function xyData() {
  const pair = (src) => {
    const xs = [], ys = [], ex = colOf(src, "e_x_px"), ey = colOf(src, "e_y_px");
    for (let i = 0; i < ex.length; i++) if (ex[i] !== null && ey[i] !== null) { xs.push(ex[i]); ys.push(ey[i]); }
    return [xs, ys];
  };
  const d = [null, pair(PV.own)];
  if (PV.cmp) d.push(pair(PV.cmp));
  return d;
}

function buildPlots() {
  for (const u of W.plots) u.destroy();
  const grid = $("plot-grid"); grid.innerHTML = "";
  W.plots = plotDefs().map((d) => makePlot(d, grid));
  W.plots.push(makeXY(grid));
  showCompareLegend();
  showGainEdits();
  PV.dirty = true;
}

function refreshPlots(force) {
  const now = performance.now();
  if (!force && (!PV.dirty || now - PV.lastDraw < 100)) return; // at most 10 redraws/s
  PV.lastDraw = now; PV.dirty = false;
  for (const u of W.plots) {
    if (u.xy) { u.setData(xyData()); continue; }
    u.setData(plotData(u.def), false);
    const [min, max] = currentRange();
    u.setScale("x", { min, max });
    if (!PV.hover) { // legend values at the cursor time
      const src = u.data[0]; let i = src.findIndex((t) => t >= PV.tNow - 1e-6); if (i < 0) i = src.length - 1;
      if (i >= 0) u.setLegend({ idx: i }, false);
    }
  }
  W.cursorT = PV.tNow;
  drawTimeline();
}

// The timeline: one mark per event at its time, its whole label beside it. Labels that would
// run into each other go on another row (up to TIMELINE_ROWS); a label near the right end
// ends at its mark instead of starting there. Only a mark with no room on any row shows as
// its line alone (its text on hover, or zoom in).
const TIMELINE_ROWS = 4, TIMELINE_ROW_PX = 15;
let measureCtx = null;
function labelPx(text, bold) {
  if (!measureCtx) measureCtx = document.createElement("canvas").getContext("2d");
  measureCtx.font = `${bold ? "600 " : ""}10px system-ui, sans-serif`; // as #timeline .mark
  return Math.ceil(measureCtx.measureText(text).width) + 9; // the text, its padding and line
}
function drawTimeline() {
  const tl = $("timeline"); const u = W.plots.find((p) => !p.xy); if (!u) return;
  const [min, max] = currentRange();
  const left = u.bbox.left / devicePixelRatio, w = u.bbox.width / devicePixelRatio;
  const width = tl.clientWidth || left + w;
  const shown = PV.events.filter(([t]) => t !== null && t >= min && t <= max).sort((a, b) => a[0] - b[0]);
  const rowEnd = new Array(TIMELINE_ROWS).fill(-Infinity);
  let rows = 1, ticks = false; // marks with no room for their label: ticks on a row of their own
  const html = shown.map(([t, kind, text]) => {
    const x = left + ((t - min) / (max - min)) * w, lw = labelPx(text, kind === "closest");
    const flip = x + lw > width; // ends at its mark
    const a = flip ? x - lw : x, b = flip ? x : x + lw;
    let r = rowEnd.findIndex((end) => end <= a - 2), bare = false;
    if (r < 0) { r = TIMELINE_ROWS; bare = ticks = true; } else { rowEnd[r] = b; rows = Math.max(rows, r + 1); }
    const cls = `mark k-${kind}${bare ? " bare" : ""}${flip && !bare ? " flip" : ""}`;
    const pos = flip && !bare ? `right:${(width - x).toFixed(1)}px` : `left:${x.toFixed(1)}px`;
    const row = bare ? -1 : r; // the ticks' row is placed below the labels once they are counted
    return `<span class="${cls}" style="${pos};top:${row < 0 ? "TICKS" : `${2 + row * TIMELINE_ROW_PX}px`}" data-t="${t}" title="t = ${fmtVal(t)} s: ${esc(text)}">${esc(text)}</span>`;
  }).join("").replaceAll("top:TICKS", `top:${2 + rows * TIMELINE_ROW_PX}px`);
  const h = `${6 + (rows + (ticks ? 1 : 0)) * TIMELINE_ROW_PX}px`;
  if (tl.style.height !== h) tl.style.height = h;
  if (html !== tl.dataset.drawn) { tl.innerHTML = html; tl.dataset.drawn = html; }
}
$("timeline").onclick = (ev) => {
  const m = ev.target.closest(".mark"); if (!m || !W.snap || !W.snap.status.replay) return;
  replay("seek", { t_s: parseFloat(m.dataset.t) });
};

// A compared pair's legend: who each sortie is, and only the gains that differ between them
// (the rest are the same in both), in the one rounding rule.
function sortieLabel(info, other, isB) {
  if (!info) return "this sortie";
  const head = `${info.file || "this sortie"} · ${info.scenario} · ${info.law}${info.seed !== undefined && info.seed !== null ? " · seed " + info.seed : ""}`;
  const g = info.gains || {}, og = (other && other.gains) || {};
  if (!Object.keys(g).length || !Object.keys(og).length) return head;
  const diff = Object.keys(g).filter((k) => k in og && og[k] !== g[k]).sort();
  if (!diff.length) return head + (isB ? " · gains: same as A" : "");
  return head + " · gains: " + diff.map((k) => `${k} ${fmtVal(g[k])}`).join(", ") + (isB ? " (the others as A)" : "");
}
function showCompareLegend() {
  const el = $("cmp-legend");
  el.hidden = !PV.cmp;
  if (!PV.cmp) { el.innerHTML = ""; return; }
  const st = W.snap && W.snap.status;
  if (PV.ownInfo && !PV.ownInfo.file) PV.ownInfo.gains = gainValues; // flying now: the gains in force
  const a = st && st.state === "idle" ? "nothing flown yet: press Start to fly beside B" : sortieLabel(PV.ownInfo, PV.cmpInfo, false);
  el.innerHTML = `<div class="lg-a"><b>A</b> (solid): ${esc(a)}</div><div class="lg-b"><b>B</b> (dashed): ${esc(sortieLabel(PV.cmpInfo, PV.ownInfo, true))}</div>`;
}

// Fetch what the plots show for the sortie on screen (status tells which).
let loadedEpoch = null, loadedCompare = null, loading = false;
async function syncPlotSources(st) {
  if (loading) return;
  const cmpName = st.compare ? st.compare.file : null;
  if (st.epoch === loadedEpoch && cmpName === loadedCompare) return;
  loading = true;
  try {
    if (st.epoch !== loadedEpoch) {
      loadedEpoch = st.epoch;
      PV.xRange = null; img.frame = null;
      if (st.replay) {
        const s = await api("GET", `/api/logs/${encodeURIComponent(st.replay.file)}/series`);
        PV.own = s; PV.events = s.events; PV.ownInfo = s.sortie;
        fillFieldChoice(s);
      } else {
        const s = await api("GET", "/api/sortie/series");
        PV.own = { t_s: s.t_s, columns: Object.keys(s.columns).length ? s.columns : emptyOwn().columns };
        PV.events = s.events; PV.ownInfo = { scenario: st.scenario, law: st.law, seed: st.seed, gains: null };
        PV.extra = []; $("add-plot-row").hidden = true;
      }
    }
    loadedCompare = cmpName;
    if (cmpName) {
      PV.cmp = await api("GET", `/api/logs/${encodeURIComponent(cmpName)}/series`);
      PV.cmpInfo = st.compare;
    } else { PV.cmp = null; PV.cmpInfo = null; }
    buildPlots();
  } catch (e) { msg($("sim-msg"), "plots: " + e.message, false); }
  finally { loading = false; }
}

function appendLive(s) { // a running sortie: one more point per telemetry message
  if (s.status.replay || s.status.epoch !== loadedEpoch || loading) return false;
  const o = PV.own; const t = s.t;
  if (o.t_s.length && t <= o.t_s[o.t_s.length - 1]) return false;
  o.t_s.push(t);
  const row = { normal_accel_m_s2: s.normal_accel_m_s2, speed_m_s: s.speed_m_s, normal_vel_m_s: s.normal_vel_m_s, e_x_px: s.e_est_px ? s.e_est_px[0] : null, e_y_px: s.e_est_px ? s.e_est_px[1] : null, range_m: s.range_m };
  for (const k of Object.keys(o.columns)) o.columns[k].push(row[k] === undefined ? null : row[k]);
  PV.dirty = true;
  return true;
}

function fillFieldChoice(s) {
  const sel = $("add-field"); sel.innerHTML = "";
  for (const k of Object.keys(s.fields || {}).sort()) { const o = document.createElement("option"); o.value = k; o.textContent = k; sel.appendChild(o); }
  $("add-plot-row").hidden = !sel.options.length;
}
$("btn-add-plot").onclick = () => {
  const key = $("add-field").value; if (!key) return;
  const unit = unitText(((PV.own && PV.own.units) || {})[key] || "-"); // from onboard/messages.py
  PV.extra.push({ title: key, unit: unit || "-", series: [{ label: key, key, color: "#2f6fe0" }] });
  buildPlots();
};
