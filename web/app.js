// Peregrine ground station page: telemetry websocket -> status, image plane, plots;
// REST API <- simulator controls and gains. Same origin; the access cookie rides along.
"use strict";

// counters the benchmark reads (groundstation bench --dashboard): telemetry messages received,
// applied (appended to the plots' series, the readouts' state updated) and painted (animation
// frames that showed new data; updates is the same count)
const W = (window.peregrine = { received: 0, applied: 0, updates: 0, lastT: null, snap: null });

// Without a GPU, Chromium renders "GPU" work in software (SwiftShader) in the GPU process, one
// for all tabs: an accelerated 2D canvas (the image plane, every plot) then sends each stroke
// there and waits for it (in a trace of 5 viewers most of each page's busy time). With a
// software renderer the page's 2D canvases are drawn on the CPU in the page's own process
// instead (willReadFrequently asks for exactly that): with 5 viewers, a page's main thread went
// from 79 % to 62 % busy and painted 2-5 frames/s instead of about 1 (groundstation bench --dashboard).
W.softwareGl = (() => {
  try {
    const gl = document.createElement("canvas").getContext("webgl");
    if (!gl) return true; // no WebGL at all: no GPU either
    const ext = gl.getExtension("WEBGL_debug_renderer_info");
    const name = String(gl.getParameter(ext ? ext.UNMASKED_RENDERER_WEBGL : gl.RENDERER));
    const lose = gl.getExtension("WEBGL_lose_context");
    if (lose) lose.loseContext();
    return /swiftshader|llvmpipe|softpipe|software/i.test(name); // as web/scene3d.js
  } catch (e) { return false; }
})();
if (W.softwareGl) {
  const getContext = HTMLCanvasElement.prototype.getContext;
  HTMLCanvasElement.prototype.getContext = function (type, options) {
    if (type === "2d") options = Object.assign({ willReadFrequently: true }, options || {});
    return getContext.call(this, type, options);
  };
}

// ------------------------------------------------------------------ plots (uPlot)
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
// ------------------------------------------------------------------ image plane
const img = { canvas: $("image"), frame: null, asked: 0, seq: 0, decoding: 0 };
img.ctx = img.canvas.getContext("2d");

function drawImagePlane(s) {
  const { ctx, canvas } = img;
  const im = s.image || { w: 640, h: 480, f: 320, vfov_deg: 73.7 };
  if (canvas.width !== im.w || canvas.height !== im.h) { canvas.width = im.w; canvas.height = im.h; }
  const cu = im.w / 2, cv = im.h / 2;
  W.imageShown = [s.t, img.frame ? img.frame.frameT : null]; // the time shown and its camera frame's
  if (img.frame) ctx.drawImage(img.frame, 0, 0, im.w, im.h);
  else {
    ctx.fillStyle = "#c9dcec"; ctx.fillRect(0, 0, im.w, im.h);
    ctx.strokeStyle = "rgba(0,0,0,.08)";
    for (let x = 0; x < im.w; x += 40) { ctx.beginPath(); ctx.moveTo(x, 0); ctx.lineTo(x, im.h); ctx.stroke(); }
    for (let y = 0; y < im.h; y += 40) { ctx.beginPath(); ctx.moveTo(0, y); ctx.lineTo(im.w, y); ctx.stroke(); }
  }
  // FOV-holding bounds: e_x held at 0 (eq. 13), and the e_y excursion the speed ramp can
  // cause, dq = atan(k_a / g) -> de_y = c_v tan(dq) / tan(vfov / 2) (eq. 16)
  ctx.setLineDash([6, 4]); ctx.strokeStyle = "#b14ad8"; ctx.lineWidth = 1.5;
  ctx.beginPath(); ctx.moveTo(cu, 0); ctx.lineTo(cu, im.h); ctx.stroke();
  // the band is centred where the target sits once the estimate has settled: the median e_y
  // of the sortie's estimates after their first TRANSIENT_S (not the first, transient one)
  const c = bandCentre();
  W.band = null;
  if (c !== null) {
    const dq = Math.atan((s.k_a || 2) / 9.81);
    const dey = (cv * Math.tan(dq)) / Math.tan(((im.vfov_deg || 73.7) * Math.PI) / 360);
    W.band = { centre: c, half: dey };
    for (const y of [cv + c - dey, cv + c + dey]) {
      ctx.beginPath(); ctx.moveTo(0, y); ctx.lineTo(im.w, y); ctx.stroke();
    }
  }
  ctx.setLineDash([]);
  ctx.strokeStyle = "#ffffff"; ctx.lineWidth = 2;
  ctx.beginPath(); ctx.moveTo(cu - 12, cv); ctx.lineTo(cu + 12, cv); ctx.moveTo(cu, cv - 12); ctx.lineTo(cu, cv + 12); ctx.stroke();
  const track = recentTrack();
  W.trackPoints = track.length;
  if (track.length > 1) {
    ctx.strokeStyle = "#2f6fe0"; ctx.lineWidth = 2; ctx.beginPath();
    track.forEach(([x, y], k) => (k ? ctx.lineTo(cu + x, cv + y) : ctx.moveTo(cu + x, cv + y)));
    ctx.stroke();
  }
  // markers are outlines drawn clear of the balloon: sized from its apparent diameter
  const dpx = s.range_m && s.target && s.target.diameter_m ? (im.f * s.target.diameter_m) / s.range_m : 0;
  // (at most MARKER_MAX_PX: near the end the balloon fills the image, the marker must show)
  const r = Math.min(Math.max(9, dpx / 2 + 6), MARKER_MAX_PX);
  if (s.e_raw_px) { // corner brackets: the balloon shows between them
    const x = cu + s.e_raw_px[0], y = cv + s.e_raw_px[1], a = r + 3, l = Math.max(5, a / 2);
    ctx.strokeStyle = "#ff9f1c"; ctx.lineWidth = 2; ctx.beginPath();
    for (const [sx, sy] of [[-1, -1], [1, -1], [1, 1], [-1, 1]]) {
      ctx.moveTo(x + sx * a, y + sy * (a - l)); ctx.lineTo(x + sx * a, y + sy * a); ctx.lineTo(x + sx * (a - l), y + sy * a);
    }
    ctx.stroke();
  }
  W.edgeArrow = null; W.endMarker = null; W.estMarker = null;
  const st = s.status || {};
  const ended = !s.e_est_px && (st.state === "finished" || (st.replay && st.outcome));
  const last = ended ? (track.length ? track[track.length - 1] : lastEstimate()) : null;
  if (last) {
    // the sortie has ended and the loop no longer estimates (after the pass it flies on while
    // it recovers): where the target was last seen
    const [ex, ey] = last, x = cu + ex, y = cv + ey;
    ctx.save(); ctx.setLineDash([4, 3]); ctx.strokeStyle = "#19c15b"; ctx.lineWidth = 2.5;
    ctx.beginPath(); ctx.arc(x, y, r, 0, 2 * Math.PI); ctx.stroke(); ctx.restore();
    ctx.fillStyle = "#0b5e2c"; ctx.font = "bold 12px sans-serif";
    ctx.fillText(`last estimate · ${st.outcome || "ended"}`, Math.min(Math.max(x + r + 4, 4), im.w - 150), Math.min(Math.max(y + 4, 14), im.h - 6));
    W.endMarker = { x, y };
  }
  if (s.e_est_px) {
    const x = cu + s.e_est_px[0], y = cv + s.e_est_px[1];
    if (x >= 0 && x <= im.w && y >= 0 && y <= im.h) {
      ctx.strokeStyle = "#19c15b"; ctx.lineWidth = 2.5;
      ctx.beginPath(); ctx.arc(x, y, r, 0, 2 * Math.PI); ctx.stroke();
      W.estMarker = { x, y, r };
    } else drawEdgeArrow(ctx, im, cu, cv, x, y);
  }
  ctx.lineWidth = 1;
}

// the sortie's last estimated image error (px), or null
function lastEstimate() {
  const ex = colOf(PV.own, "e_x_px"), ey = colOf(PV.own, "e_y_px");
  for (let i = Math.min(ex.length, ey.length) - 1; i >= 0; i--) if (ex[i] !== null && ey[i] !== null) return [ex[i], ey[i]];
  return null;
}

const TRANSIENT_S = 1.0, TRACK_S = 1.5, MARKER_MAX_PX = 40;
let bandCache = { n: -1, src: null, c: null };
function bandCentre() {
  const src = PV.own, ys = (src.columns && src.columns.e_y_px) || [];
  // the estimates up to the pass: after it the vehicle recovers with the target behind it
  const st = (W.snap && W.snap.status) || {}, tPass = st.intercept_time_s ?? Infinity;
  if (bandCache.src === src && bandCache.n === ys.length && bandCache.tPass === tPass) return bandCache.c;
  let t0 = null; const vals = [];
  for (let i = 0; i < ys.length; i++) {
    if (src.t_s[i] > tPass) break;
    if (ys[i] === null || ys[i] === undefined) continue;
    if (t0 === null) t0 = src.t_s[i];
    if (src.t_s[i] >= t0 + TRANSIENT_S) vals.push(ys[i]);
  }
  vals.sort((a, b) => a - b);
  bandCache = { n: ys.length, src, tPass, c: vals.length ? vals[Math.floor(vals.length / 2)] : null };
  return bandCache.c;
}
// The estimates of the last TRACK_S before the time shown (running or replayed alike).
function recentTrack() {
  const src = PV.own, ex = colOf(src, "e_x_px"), ey = colOf(src, "e_y_px"), t = src.t_s, out = [];
  let i = t.length - 1;
  while (i >= 0 && t[i] > PV.tNow + 1e-6) i--;
  for (; i >= 0 && t[i] >= PV.tNow - TRACK_S; i--) if (ex[i] !== null && ey[i] !== null && ex[i] !== undefined) out.push([ex[i], ey[i]]);
  return out.reverse();
}

// An estimate outside the image: an arrow on the edge pointing at it, with its distance.
function drawEdgeArrow(ctx, im, cu, cv, x, y) {
  const dx = x - cu, dy = y - cv, m = 18;
  const k = Math.min(Math.abs((cu - m) / (dx || 1e-9)), Math.abs((cv - m) / (dy || 1e-9)));
  const ex = cu + dx * k, ey = cv + dy * k, ang = Math.atan2(dy, dx);
  ctx.save(); ctx.translate(ex, ey); ctx.rotate(ang);
  ctx.fillStyle = "#19c15b"; ctx.strokeStyle = "#0b5e2c"; ctx.lineWidth = 1.5;
  ctx.beginPath(); ctx.moveTo(14, 0); ctx.lineTo(-8, -10); ctx.lineTo(-8, 10); ctx.closePath(); ctx.fill(); ctx.stroke();
  ctx.restore();
  const off = Math.hypot(dx, dy) - Math.hypot(ex - cu, ey - cv);
  ctx.fillStyle = "#0b5e2c"; ctx.font = "bold 12px sans-serif";
  ctx.fillText(`estimate ${off.toFixed(0)} px outside`, Math.min(Math.max(ex - 60, 4), im.w - 150), Math.min(Math.max(ey + (ey > cv ? -16 : 24), 14), im.h - 6));
  W.edgeArrow = { x: ex, y: ey };
}

// ------------------------------------------------------------------ status
// DOM writes only when something changed: a redraw that rewrites unchanged text still costs
// style and layout work, 40 times a second in every viewer
function setText(el, text) { if (el.textContent !== text) el.textContent = text; }
function setBadge(id, text, cls) {
  const el = $(id), c = "badge" + (cls ? " " + cls : "");
  setText(el, text); if (el.className !== c) el.className = c;
}
let lastStatusParts = "";
let lastGainsStamp = null; // gains_pending and the last applied time, as last shown

let shownEpoch = -1; // the newest sortie shown: a status from before it (a telemetry message
// sent before a Start's answer, read after it) is not shown over it
function showStatus(st) {
  if (st.epoch !== undefined) { if (st.epoch < shownEpoch) return; shownEpoch = st.epoch; }
  setBadge("st-state", st.state, st.state === "running" ? "ok" : st.state === "finished" ? "warn" : "");
  const profile = st.profile === "ideal" ? " · IDEAL SENSORS (analysis only)" : st.profile ? ` · ${st.profile}` : "";
  setBadge("st-scenario", `${st.scenario} · ${st.law} · seed ${st.seed} · ${st.camera}${profile} · ${st.speed === "max" ? "max speed" : st.speed + "×"}`);
  setBadge("st-time", `t = ${Number(st.time_s).toFixed(2)} s`);
  if (st.outcome) setBadge("st-outcome", `${st.outcome} · miss ${fmtVal(st.miss_m)} m`, st.outcome === "HIT" ? "ok" : "bad");
  else setBadge("st-outcome", "no outcome");
  if (st.dkf) {
    const since = st.dkf.time_since_detection_s;
    const txt = !st.dkf.acquired ? "DKF waiting" : st.dkf.lost ? "DKF LOST" : `DKF ok · ${since === null ? "—" : (1000 * since).toFixed(0) + " ms"}`;
    setBadge("st-dkf", txt, st.dkf.lost && st.dkf.acquired ? "bad" : st.dkf.acquired ? "ok" : "");
  } else setBadge("st-dkf", "DKF —");
  setBadge("st-rate", st.state === "running" ? `loop ${st.loop_rate_hz} Hz` : "loop — Hz");
  setText($("btn-pause"), st.state === "paused" ? "Resume" : "Pause");
  showLive(st.live);
  showReplay(st.replay);
  syncControls(st);
  showStateChange(st);
  syncPlotSources(st);
  const parts = JSON.stringify([st.recording, st.gains_source, st.gains_edited, st.gains_note, st.gains_recorded]);
  if (parts !== lastStatusParts) { // rarely changes: not redone every frame
    lastStatusParts = parts;
    showRecording(st.recording);
    showGainsInForce(st);
    markGains();
  }
  let applied = "";
  if (st.gains_applied_time_s !== null && st.gains_applied_time_s !== undefined)
    applied = `last edit applied at t = ${fmtVal(st.gains_applied_time_s)} s`;
  if (st.gains_pending) applied = st.live ? "edit sent: waiting for the vehicle's PARAM_VALUE" : "edit pending: next control tick";
  setText($("gains-applied"), applied);
  // an edit takes effect after the PUT returns (the next tick; in live mode the vehicle's
  // PARAM_VALUE): the panel then shows the values in force, not those read at the PUT
  const stamp = `${!!st.gains_pending} ${st.gains_applied_time_s}`;
  if (lastGainsStamp !== null && stamp !== lastGainsStamp && !st.gains_pending) refreshGainValues();
  lastGainsStamp = stamp;
}

// The recording of the sortie on screen: its file, and any error as a banner that stays.
function showRecording(rec) {
  const b = $("rec-banner");
  if (!rec) { b.hidden = true; return; }
  b.hidden = false;
  if (rec.error) { b.className = "banner err"; b.textContent = `Recording failed: ${rec.error}. The sortie goes on but is ${rec.file ? "no longer" : "not"} recorded.`; }
  else { b.className = "banner ok"; b.textContent = `${rec.closed ? "Recorded to" : "Recording to"} ${rec.file}`; }
}

// Header: which gain set flies, with the operator's edits marked (*).
function showGainsInForce(st) {
  if (st.gains_source === undefined) { setBadge("st-gains", "gains: the vehicle's"); return; }
  const ed = Object.entries(st.gains_edited || {});
  let txt = `gains: ${st.gains_source}` + (ed.length ? " + edits " + ed.map(([k, [a, b]]) => `${k}* ${fmtVal(a)}→${fmtVal(b)}`).join(", ") : "");
  if (st.gains_recorded) { // a replayed sortie: its own gains, those not at their default
    const rg = Object.entries(st.gains_recorded);
    txt += rg.length ? " · not default: " + rg.map(([k, v]) => `${k} ${fmtVal(v)}`).join(", ") : " · all default";
  }
  setBadge("st-gains", txt, ed.length ? "warn" : "");
  $("gains-source").textContent = `flying: ${st.gains_source}${ed.length ? ` with ${ed.length} edit${ed.length > 1 ? "s" : ""}` : ""}`;
  const note = $("gains-note"); note.hidden = !st.gains_note; note.textContent = st.gains_note || "";
  W.gainsEdited = st.gains_edited || {};
}

// The controls show what is in force: the speed always, the sortie's scenario, law, seed and
// camera whenever a new sortie appears (and on page load), unless the operator is editing one.
let controlsEpoch = null;
function syncControls(st) {
  const set = (id, v) => { const el = $(id); if (v === null || v === undefined || document.activeElement === el) return; if (el.tagName !== "SELECT" || [...el.options].some((o) => o.value === String(v))) el.value = String(v); };
  set("speed", st.speed);
  if (st.epoch === controlsEpoch || st.live) return;
  if (st.state !== "replay" && !$("scenario").options.length) return; // not listed yet: next time
  controlsEpoch = st.epoch;
  // idle too: after a Reset the header names the last sortie's settings, and Start flies them
  set("law", st.law); set("camera", st.camera); set("seed", st.seed);
  if (!st.replay && [...$("scenario").options].some((o) => o.value === st.scenario) && $("scenario").value !== st.scenario) { set("scenario", st.scenario); loadToml(); }
}

// The simulator's message line follows the sortie: no "started" left once it has ended; a
// page loaded after the end says how it ended.
let lastState = null, studyFlying = null; // studyFlying: {n, epoch} of a trial flying
function showTrialEnd(st) { // "trial #n flying" only while it flies
  if (studyFlying === null || (st.state === "running" && st.epoch === studyFlying.epoch)) return;
  const tr = studyFlying; studyFlying = null;
  if (st.epoch === tr.epoch && st.state === "finished") msg($("study-msg"), `trial #${tr.n} flown: ${st.outcome || "no outcome"}${st.miss_m !== null && st.miss_m !== undefined ? `, miss ${fmtVal(st.miss_m)} m` : ""}`, st.outcome === "HIT");
  else msg($("study-msg"), "", true);
}
function showStateChange(st) {
  showTrialEnd(st);
  if (st.state === lastState || st.live) return;
  const prev = lastState; lastState = st.state;
  if (prev === null && st.state !== "finished") return; // a page (re)loaded: only the outcome is worth saying
  if (st.state === "finished") msg($("sim-msg"), `finished: ${st.outcome || "no outcome"}${st.miss_m !== null && st.miss_m !== undefined ? `, miss ${fmtVal(st.miss_m)} m` : ""}${st.intercept_time_s !== undefined ? ` at t = ${fmtVal(st.intercept_time_s)} s` : ""}`, st.outcome === "HIT");
  else if (st.state === "running") msg($("sim-msg"), prev === "paused" ? "running" : "started", true);
  else if (st.state === "paused") msg($("sim-msg"), "paused", true);
  else if (st.state === "idle") msg($("sim-msg"), "reset", true);
  else if (st.state === "replay") msg($("sim-msg"), `replaying ${st.replay ? st.replay.file : ""}`, true);
}

// ------------------------------------------------------------------ live vehicle
function showLive(lv) {
  $("live-panel").hidden = !lv;
  if (!lv) return;
  $("sim-panel").hidden = true;
  $("lv-url").textContent = `${lv.url}${lv.signed ? " · signed" : " · unsigned"}`;
  $("lv-link").textContent = lv.link; $("lv-link").className = lv.link === "up" ? "ok" : "err";
  $("lv-state").textContent = lv.onboard_state;
  $("lv-fc").textContent = `${lv.fc_link ? "link up" : "no link"} · ${lv.fc_mode} · ${lv.fc_armed ? "armed" : "disarmed"}${lv.target_reported ? " · target reports its position" : ""}`;
  const num = (x, d) => (x === null || x === undefined ? "—" : Number(x).toFixed(d));
  $("lv-loop").textContent = `jitter p99 ${num(lv.loop_jitter_p99_ms, 2)} ms · capture→command ${num(lv.latency_ms, 1)} ms · overruns ${num(lv.overruns, 0)}`;
  const sends = lv.params_sends || {};
  const pend = Object.keys(lv.params_pending).map((n) => (sends[n] > 1 ? `${n} (sent ${sends[n]}×)` : n)), refused = Object.values(lv.params_refused);
  $("lv-params").textContent = `${lv.params_received}/${lv.params_total} read` + (pend.length ? ` · waiting for PARAM_VALUE: ${pend.join(", ")}` : "") + (refused.length ? ` · not applied: ${refused.join("; ")}` : "");
  $("lv-ack").textContent = lv.last_ack ? `${lv.last_ack.command}: ${lv.last_ack.result}` : "—";
  $("lv-rates").textContent = Object.entries(lv.rates_hz).map(([k, v]) => `${k} ${v}`).join(" · ") + (lv.bad_frames ? ` · bad frames ${lv.bad_frames}` : "");
  const ev = $("lv-events"); ev.innerHTML = "";
  for (const e of lv.events.slice().reverse()) {
    const d = document.createElement("div");
    d.className = e.severity <= 3 ? "sev-err" : e.severity === 4 ? "sev-warn" : "";
    d.textContent = `${e.source}: ${e.text}`; ev.appendChild(d);
  }
}
async function liveCommand(action) {
  try { const r = await api("POST", "/api/live/" + action); msg($("live-msg"), `${action}: ${r.ack.result}`, true); }
  catch (e) { msg($("live-msg"), e.message, false); }
}
$("btn-live-start").onclick = () => liveCommand("start");
$("btn-live-abort").onclick = () => liveCommand("abort");

// ------------------------------------------------------------------ telemetry
// Each message is taken in at once (cheap: parse, append to the plots' data); the views are
// redrawn at most once per animation frame, so a slow machine draws less often instead of
// falling behind. window.peregrine counts the messages received, those applied to the plots'
// series and readouts (every one of a running sortie) and the redraws that showed new data.
let pending = null;
let frameRequested = false;

function takeSnapshot(s) {
  W.received += 1; W.snap = s;
  if (s.events && s.events.length !== PV.events.length && !loading) { PV.events = s.events; PV.dirty = true; showGainEdits(); }
  if (s.t !== undefined) {
    W.lastT = s.t;
    // a replayed frame comes with its recorded time: the last decoded for the newest
    // snapshot is shown (an older one decoded late is dropped), none where none was recorded.
    // While a replayed frame decodes the page is not redrawn: the image plane then never
    // shows a newer time over the frame before (the frame follows the cursor as it plays)
    if (s.frame_t_s === null) { img.frame = null; img.seq = ++img.asked; W.frameT = null; W.frameFor = s.t; }
    if (s.frame_jpeg_b64) {
      const im = new Image(), seq = ++img.asked, ft = s.frame_t_s, at = s.t;
      im.frameT = ft === undefined ? null : ft;
      if (ft !== undefined) img.decoding = seq;
      const done = () => {
        if (img.decoding === seq) img.decoding = 0;
        if (!frameRequested) { frameRequested = true; requestAnimationFrame(redraw); }
      };
      im.onload = () => {
        if (seq >= img.seq) { img.seq = seq; img.frame = im; W.frameT = im.frameT; W.frameFor = at; pending = pending || W.snap; }
        done();
      };
      im.onerror = done;
      im.src = "data:image/jpeg;base64," + s.frame_jpeg_b64;
    }
    if (appendLive(s)) W.applied += 1;
    if (PV.tNow !== s.t) { PV.tNow = s.t; PV.dirty = true; }
  }
  pending = s;
  if (!frameRequested) { frameRequested = true; requestAnimationFrame(redraw); }
}

function redraw() {
  frameRequested = false;
  if (img.decoding) return; // drawn once the replayed frame has decoded (takeSnapshot)
  const s = pending; if (!s) return;
  pending = null;
  W.updates += 1; W.shownT = s.t;
  showStatus(s.status);
  drawImagePlane(s);
  refreshPlots(false);
  if (PV.dirty && !plotTimer) plotTimer = setTimeout(() => { plotTimer = null; refreshPlots(false); }, 110);
}
let plotTimer = null;

function connect() {
  const ws = new WebSocket((location.protocol === "https:" ? "wss://" : "ws://") + location.host + "/ws/telemetry");
  // a hidden tab asks for no camera frames: it cannot show them
  const wantFrames = () => { if (ws.readyState === 1) ws.send(JSON.stringify({ frames: document.visibilityState === "visible" })); };
  ws.onopen = () => { setBadge("st-link", "telemetry: live", "ok"); wantFrames(); };
  document.addEventListener("visibilitychange", wantFrames);
  ws.onmessage = (ev) => takeSnapshot(JSON.parse(ev.data));
  ws.onclose = () => { setBadge("st-link", "telemetry: reconnecting", "bad"); setTimeout(connect, 1000); };
}

// ------------------------------------------------------------------ replay
let scrubbing = false, lastSeek = 0, seekTimer = null;
function showReplay(rp) {
  $("replay-panel").hidden = !rp;
  if (!rp) return;
  setText($("rp-file"), `${rp.file}${rp.status !== "ok" ? " (" + rp.status + ": replayed up to the damage)" : ""}${rp.compare ? " · compared with " + rp.compare : ""}`);
  const scrub = $("rp-scrub");
  scrub.max = rp.duration_s;
  if (!scrubbing) scrub.value = rp.t_s;
  setText($("rp-time"), `${Number(rp.t_s).toFixed(2)} / ${Number(rp.duration_s).toFixed(2)} s · ${rp.speed_x}×`);
  $("rp-play").textContent = rp.playing ? "Pause" : "Play";
}
async function replay(action, body) {
  try { showStatus(await api("POST", "/api/replay/" + action, body)); } catch (e) { msg($("rp-msg"), e.message, false); }
}
$("rp-play").onclick = () => replay($("rp-play").textContent === "Play" ? "play" : "pause");
$("rp-closest").onclick = () => replay("closest");
$("rp-scrub").oninput = () => {
  scrubbing = true;
  const go = () => { lastSeek = performance.now(); replay("seek", { t_s: parseFloat($("rp-scrub").value) }); };
  clearTimeout(seekTimer);
  if (performance.now() - lastSeek > 80) go(); else seekTimer = setTimeout(go, 80);
};
$("rp-scrub").onchange = () => { scrubbing = false; replay("seek", { t_s: parseFloat($("rp-scrub").value) }); };

// ?compare=NAME: overlay that recorded sortie on the one on screen (the server keeps it, so a
// reload or another viewer shows the same comparison).
async function compareFromUrl() {
  const name = new URLSearchParams(location.search).get("compare");
  if (!name) return;
  const st = await api("GET", "/api/status");
  if (st.compare && st.compare.file === name) return;
  try { showStatus(await api("POST", "/api/replay/compare", { name })); }
  catch (e) { msg($("rp-msg").closest(".panel").hidden ? $("sim-msg") : $("rp-msg"), `compare with ${name}: ${e.message}`, false); }
}

// ------------------------------------------------------------------ simulator controls
async function loadScenarios() {
  const list = await api("GET", "/api/scenarios");
  const sel = $("scenario"); sel.innerHTML = "";
  for (const s of list) {
    const o = document.createElement("option"); o.value = s.name; o.textContent = `${s.name} (${s.motion})`; o.title = s.description;
    sel.appendChild(o);
  }
  const st = await api("GET", "/api/status"); // the scenario the header names, else the default
  sel.value = !st.replay && list.some((s) => s.name === st.scenario) ? st.scenario : "cv-top-to-bottom";
  await loadToml();
}

async function loadToml() {
  const r = await api("GET", "/api/scenarios/" + encodeURIComponent($("scenario").value));
  $("toml").value = r.toml;
}

$("scenario").onchange = loadToml;
$("toml-file").onchange = async (ev) => {
  const f = ev.target.files[0]; if (!f) return;
  $("toml").value = await f.text(); $("use-toml").checked = true; $("toml-box").open = true;
};
$("btn-validate").onclick = async () => {
  try { const r = await api("POST", "/api/scenarios/validate", { toml: $("toml").value }); msg($("sim-msg"), `valid: ${r.name} (${r.motion})`, true); }
  catch (e) { msg($("sim-msg"), e.message, false); }
};

// Start applies the values typed in the gains panel and not yet applied (what an operator
// who typed them expects to fly); one of them refused, nothing starts and nothing is applied.
$("btn-start").onclick = async () => {
  const body = { law: $("law").value, seed: parseInt($("seed").value || "0", 10), camera: $("camera").value, speed: $("speed").value };
  if ($("use-toml").checked) body.toml = $("toml").value; else body.scenario = $("scenario").value;
  if ($("wind-override").checked) {
    body.wind_mean_m_s = ["wind-x", "wind-y", "wind-z"].map((id) => parseFloat($(id).value || "0"));
    body.gust_m_s = parseFloat($("gust").value || "0");
  }
  const typed = typedGains();
  if (Object.keys(typed).length) {
    try { await api("PUT", "/api/gains", typed); }
    catch (e) {
      const refused = (e.data && e.data.refused) || {};
      const names = Object.keys(refused);
      markBad(names);
      msg($("sim-msg"), names.length ? "not started: a typed gain is refused (fix or clear it): " + names.map((k) => refusal(k, String(typed[k]), refused[k])).join(" ") : e.message, false);
      return;
    }
  }
  try {
    showStatus(await api("POST", "/api/sortie/start", body));
    const applied = Object.entries(typed).map(([k, v]) => `${k} = ${v}`);
    msg($("sim-msg"), applied.length ? `started, with your typed value${applied.length > 1 ? "s" : ""} applied: ${applied.join(", ")}` : "started", true);
    await loadGains();
  } catch (e) { msg($("sim-msg"), e.message, false); }
};
$("btn-pause").onclick = async () => {
  const path = $("btn-pause").textContent === "Resume" ? "/api/sortie/resume" : "/api/sortie/pause";
  try { showStatus(await api("POST", path)); } catch (e) { msg($("sim-msg"), e.message, false); }
};
$("btn-step").onclick = async () => { try { showStatus(await api("POST", "/api/sortie/step")); } catch (e) { msg($("sim-msg"), e.message, false); } };
$("btn-reset").onclick = async () => { try { showStatus(await api("POST", "/api/sortie/reset")); msg($("sim-msg"), "reset", true); } catch (e) { msg($("sim-msg"), e.message, false); } };
$("speed").onchange = async () => { try { await api("PUT", "/api/sortie/speed", { speed: $("speed").value }); } catch (e) { msg($("sim-msg"), e.message, false); } };

// ------------------------------------------------------------------ gains
// Like a parameter editor: grouped, meaning and unit inline, values that differ from the
// default highlighted, a reset per gain, search, the edits made during this sortie, and named
// gain sets saved, loaded, downloaded and uploaded. A refused value goes back to the one in force.
let gainValues = {}, gainSpecs = {};
// Reads of the gains in force can cross (a read after Apply and one after the vehicle's
// PARAM_VALUE): the values of the latest read asked for win, whatever order the answers come in.
let gainsAsked = 0, gainsShown = 0;
async function readGains() {
  const n = ++gainsAsked;
  const g = await api("GET", "/api/gains");
  if (n > gainsShown) { gainsShown = n; gainValues = g.values; }
  return g;
}
async function loadGains() {
  const g = await readGains();
  if (PV.cmp) showCompareLegend(); // B's gains are told against A's: the legend needs these
  const tb = document.querySelector("#gains tbody"); tb.innerHTML = "";
  let group = null;
  for (const s of g.specs) {
    gainSpecs[s.name] = s;
    if (s.group !== group) {
      group = s.group;
      const gr = document.createElement("tr"); gr.className = "group"; gr.innerHTML = `<th colspan="7">${esc(group || "")}</th>`; tb.appendChild(gr);
    }
    const tr = document.createElement("tr"); tr.dataset.gain = s.name; tr.dataset.search = `${s.name} ${s.meaning} ${s.group}`.toLowerCase();
    tr.innerHTML = `<td class="gname">${esc(s.name)}</td><td><input data-gain="${esc(s.name)}" value="${gainValues[s.name]}"></td><td>${esc(unitText(s.unit))}</td>` +
      `<td class="meaning">${esc(s.meaning)}</td><td>${s.min} to ${s.max}</td><td>${s.default}</td><td><button class="mini" data-reset="${esc(s.name)}" title="back to the default, ${s.default}">reset</button></td>`;
    tb.appendChild(tr);
  }
  tb.querySelectorAll("input").forEach((inp) => {
    inp.oninput = () => inp.classList.toggle("changed", inp.value !== String(gainValues[inp.dataset.gain]));
  });
  markGains();
  filterGains();
  const names = await api("GET", "/api/gainsets");
  const sel = $("gainsets"); const keep = sel.value; sel.innerHTML = "";
  for (const n of names) { const o = document.createElement("option"); o.value = n; o.textContent = n; sel.appendChild(o); }
  if (names.includes(keep)) sel.value = keep;
  gainsetLink();
}
// The values in force into the fields, except a field the operator is editing.
async function refreshGainValues() {
  try { await readGains(); } catch (e) { return; }
  if (PV.cmp) showCompareLegend();
  document.querySelectorAll("#gains input[data-gain]").forEach((inp) => {
    if (document.activeElement === inp || inp.classList.contains("changed")) return;
    inp.value = gainValues[inp.dataset.gain];
  });
  markGains();
}
function markGains() {
  document.querySelectorAll("#gains tr[data-gain]").forEach((tr) => {
    const n = tr.dataset.gain, s = gainSpecs[n]; if (!s) return;
    tr.classList.toggle("nondefault", gainValues[n] !== s.default);
    tr.classList.toggle("edited", n in (W.gainsEdited || {}));
    tr.querySelector("button[data-reset]").disabled = gainValues[n] === s.default;
  });
}
function filterGains() {
  const raw = $("gain-search").value.trim(), q = raw.toLowerCase();
  let shown = 0;
  document.querySelectorAll("#gains tr[data-gain]").forEach((tr) => { tr.hidden = !!q && !tr.dataset.search.includes(q); if (!tr.hidden) shown++; });
  // a group's heading only over gains shown
  document.querySelectorAll("#gains tr.group").forEach((gr) => {
    let e = gr.nextElementSibling, any = false;
    while (e && e.dataset.gain) { any = any || !e.hidden; e = e.nextElementSibling; }
    gr.hidden = !any;
  });
  const none = $("gains-none");
  none.hidden = shown > 0; none.textContent = shown ? "" : `no gain matches "${raw}"`;
}
$("gain-search").oninput = filterGains;
function gainsetLink() {
  const n = $("gainsets").value, a = $("gainset-download");
  a.href = n ? `/api/gainsets/${encodeURIComponent(n)}/file` : "#"; a.hidden = !n; a.download = n ? `${n}.toml` : "";
}
$("gainsets").onchange = gainsetLink;

function showGainEdits() {
  const ol = $("gain-edits");
  const edits = PV.events.filter(([, kind]) => kind === "gain");
  ol.innerHTML = edits.length ? edits.map(([t, , text]) => `<li>${t === null ? "before the sortie" : "t = " + fmtVal(t) + " s"}: ${esc(text)}</li>`).join("") : "<li class=none>none</li>";
}

// One sentence on why a value is refused (the range check is the server's; this words it).
function refusal(name, raw, detail) {
  const s = gainSpecs[name], v = Number(raw);
  if (!s) return detail;
  const unit = unitText(s.unit) ? " " + unitText(s.unit) : "";
  let why = detail.replace(/\s+-$/, "");
  if (raw.trim() === "" || !isFinite(v)) why = `"${raw}" is not a number`;
  else if (v < s.min || v > s.max) why = `${v} is outside ${s.min} to ${s.max}${unit}`;
  return `${name} refused: ${why}; it stays ${gainValues[name]}${unit}.`;
}

// The values typed and not applied: name -> number (or the text, which the server refuses).
function typedGains() {
  const changes = {};
  document.querySelectorAll("#gains input[data-gain]").forEach((inp) => {
    if (inp.value !== String(gainValues[inp.dataset.gain])) {
      const v = Number(inp.value);
      changes[inp.dataset.gain] = inp.value.trim() === "" || !isFinite(v) ? inp.value : v;
    }
  });
  return changes;
}
function markBad(names) {
  document.querySelectorAll("#gains input[data-gain]").forEach((inp) => inp.classList.toggle("bad", names.includes(inp.dataset.gain)));
}
// Apply: the valid edits fly, every refused one is named with its reason and its field goes
// back to the value in force.
async function applyGains(changes) {
  if (!Object.keys(changes).length) { msg($("gains-msg"), "nothing changed", true); return; }
  try {
    const r = await api("PUT", "/api/gains?valid_only=true", changes);
    const refused = r.refused || {};
    const applied = Object.entries(changes).filter(([k]) => !(k in refused)).map(([k, v]) => `${k} = ${v}`);
    if (applied.length) await loadGains(); // the values in force, the new ones among them
    for (const k of Object.keys(refused)) { // a refused field goes back to the value in force
      const el = document.querySelector(`#gains input[data-gain="${k}"]`);
      if (el) { el.value = gainValues[k]; el.classList.remove("changed"); }
    }
    const why = Object.keys(refused).map((k) => refusal(k, String(changes[k]), refused[k]));
    const text = (applied.length ? [`applied: ${applied.join(", ")}.`] : []).concat(why).join(" ");
    msg($("gains-msg"), text, !why.length);
    markBad(Object.keys(refused));
  } catch (e) { msg($("gains-msg"), e.message, false); }
}
$("btn-apply-gains").onclick = () => applyGains(typedGains());
document.querySelector("#gains tbody").onclick = (ev) => {
  const b = ev.target.closest("button[data-reset]"); if (!b) return;
  const n = b.dataset.reset; applyGains({ [n]: gainSpecs[n].default });
};
$("btn-reset-gains").onclick = async () => { try { await api("POST", "/api/gains/reset"); await loadGains(); msg($("gains-msg"), "your edits are dropped: the gain set in force flies", true); } catch (e) { msg($("gains-msg"), e.message, false); } };
$("btn-save-gainset").onclick = async () => {
  const name = $("gainset-name").value.trim();
  if (!name) { msg($("gains-msg"), "give the gain set a name first.", false); $("gainset-name").focus(); return; }
  try { await api("PUT", "/api/gainsets/" + encodeURIComponent(name)); await loadGains(); $("gainsets").value = name; gainsetLink(); msg($("gains-msg"), `saved '${name}'`, true); }
  catch (e) { msg($("gains-msg"), e.message, false); }
};
$("btn-load-gainset").onclick = async () => {
  const name = $("gainsets").value; if (!name) { msg($("gains-msg"), "no gain set saved yet.", false); return; }
  try { await api("POST", `/api/gainsets/${encodeURIComponent(name)}/load`); await loadGains(); msg($("gains-msg"), `loaded '${name}': it replaces the gains in force and your edits`, true); }
  catch (e) { msg($("gains-msg"), e.message, false); }
};
$("gainset-upload").onchange = async (ev) => {
  const f = ev.target.files[0]; if (!f) return;
  const name = ($("gainset-name").value.trim() || f.name.replace(/\.toml$/i, "")).replace(/[^A-Za-z0-9_.-]/g, "_");
  try { await api("POST", "/api/gainsets/upload", { name, toml: await f.text() }); await loadGains(); $("gainsets").value = name; gainsetLink(); msg($("gains-msg"), `uploaded '${name}': press Load to fly it`, true); }
  // refused: the server's sentence names the file, says nothing was saved and lists every problem
  catch (e) { msg($("gains-msg"), e.message, false); }
  ev.target.value = "";
};

// The 3D view only in a visible tab: a hidden one drops its viser connection (viser replays
// the whole scene when it reconnects), so background tabs cost the machine almost nothing.
// It is loaded from the server's 3D-view port when there is one (GET /api/scene): another
// origin, so the browser gives it a process of its own and its WebGL never stalls this page's
// thread (see SceneListener in groundstation/app/scene_listener.py). It draws itself only as often as
// the eye needs and moves viser's notices out of the way: web/scene3d.js, run in its page.
let sceneUrl = null;
function syncSceneToVisibility() {
  const frame = $("viser");
  const visible = document.visibilityState === "visible";
  if (sceneUrl === null) return;
  if (visible && frame.dataset.live !== "1") { frame.src = sceneUrl; frame.dataset.live = "1"; }
  if (!visible && frame.dataset.live === "1") { frame.src = "about:blank"; frame.dataset.live = "0"; }
}
document.addEventListener("visibilitychange", syncSceneToVisibility);
api("GET", "/api/scene").then((r) => r.port, () => null).then((port) => {
  sceneUrl = port ? `${location.protocol}//${location.hostname}:${port}/viser/` : "/viser/";
  syncSceneToVisibility();
});

// ------------------------------------------------------------------ gain studies
// The Optuna studies `groundstation tune` stored: a trials table, the best-so-far loss per
// trial (uPlot), and "Fly" on any trial: its gains fly the study's first training sortie on
// screen, with the same sortie flown with the defaults overlaid (the compare legend says which).
const ST = { plot: null, detail: null };
async function loadStudies() {
  const list = await api("GET", "/api/studies");
  const sel = $("study"), keep = sel.value;
  sel.innerHTML = "";
  for (const s of list) {
    const o = document.createElement("option"); o.value = s.name;
    o.textContent = `${s.name} · ${s.trials} trials${s.best_value !== null ? " · best " + fmtVal(s.best_value) : ""}`;
    sel.appendChild(o);
  }
  $("study-empty").hidden = list.length > 0;
  $("study-empty").textContent = "No gain studies yet: `groundstation tune CAMPAIGN --gains K_y,k_p` stores one (under this server's data folder); it is listed here.";
  if (!list.length) { $("study-info").textContent = ""; $("trials").querySelector("tbody").innerHTML = ""; if (ST.plot) { ST.plot.destroy(); ST.plot = null; } return; }
  if (keep && list.some((s) => s.name === keep)) sel.value = keep;
  await showStudy(sel.value);
}
async function showStudy(name) {
  const d = (ST.detail = await api("GET", "/api/studies/" + encodeURIComponent(name)));
  const def = d.definition || {};
  const done = d.trials.filter((t) => t.value !== null);
  const best = done.length ? done.reduce((a, b) => (b.value < a.value ? b : a)) : null;
  $("study-info").textContent = `${def.target || "?"} · law ${def.law || "?"} · objective ${def.objective || "?"} · ${done.length} of ${d.trials.length} trials done${best ? " · best #" + best.number : ""}`;
  const rows = [...d.trials].sort((a, b) => (a.value ?? Infinity) - (b.value ?? Infinity));
  $("trials").querySelector("tbody").innerHTML = rows.map((t) => {
    const g = Object.entries(t.params).map(([k, v]) => `${k} ${fmtVal(v)}`).join(", ");
    const f = t.figures || {};
    return `<tr data-trial="${t.number}" class="${best && t.number === best.number ? "best" : ""}"><td>#${t.number}${t.defaults ? " (defaults)" : ""}</td><td>${esc(t.state.toLowerCase())}</td>
      <td>${fmtVal(t.value)}</td><td>${f.success_rate === null || f.success_rate === undefined ? "—" : (100 * f.success_rate).toFixed(0) + " %"}</td>
      <td>${fmtVal(f.cep_m)}</td><td class="gains">${esc(g)}</td>
      <td>${t.value === null ? "" : `<button data-act="fly" title="fly these gains, the defaults overlaid">Fly</button>`}</td></tr>`;
  }).join("");
  const x = d.trials.map((t) => t.number), y = d.trials.map((t) => t.value), b = d.best_so_far;
  const box = $("study-plot"), w = Math.max(260, box.clientWidth || 420);
  if (ST.plot) ST.plot.destroy();
  ST.plot = new uPlot({
    width: w, height: 170, legend: { show: true },
    scales: { x: { time: false } },
    axes: [{ label: "trial", labelSize: 16, size: 34, incrs: [1, 2, 5, 10, 20, 50, 100, 200, 500, 1000], values: (u, vals) => { W.studyTicks = vals; return vals.map((v) => (Number.isInteger(v) ? String(v) : "")); } },
      { label: "loss (lower is better)", labelSize: 16, size: 52, values: (u, vals) => vals.map(fmtVal) }],
    series: [{ label: "trial" }, { label: "loss", stroke: "#9aa5b1", width: 0, points: { show: true, size: 5, fill: "#9aa5b1" } },
      { label: "best so far", stroke: "#d7263d", width: 2, paths: uPlot.paths.stepped({ align: 1 }), points: { show: false } }],
  }, [x, y, b], box);
  W.study = { name, trials: d.trials.length, best: best ? best.number : null };
  W.studyPlot = () => ST.plot.data[2];
}
$("study").onchange = () => showStudy($("study").value).catch((e) => msg($("study-msg"), e.message, false));
$("btn-studies-refresh").onclick = () => loadStudies().catch((e) => msg($("study-msg"), e.message, false));
$("trials").onclick = async (ev) => {
  const btn = ev.target.closest("button[data-act=fly]"); if (!btn) return;
  const n = btn.closest("tr").dataset.trial, name = $("study").value;
  msg($("study-msg"), `flying the defaults, then trial #${n}…`, true);
  try {
    const st = await api("POST", `/api/studies/${encodeURIComponent(name)}/trials/${n}/fly`, { speed: $("speed").value || "1" });
    msg($("study-msg"), `trial #${n} flying at ${st.speed}×, the defaults' sortie overlaid (B)`, true);
    studyFlying = { n, epoch: st.epoch };
    showStatus(st);
    await loadGains(); // the trial's gains are in force: the panel shows them
  } catch (e) { msg($("study-msg"), e.message, false); }
};

// the option lists (laws, cameras, speeds) come from GET /api/meta first: the controls can
// then show what is in force
window.peregrineMeta.catch((e) => msg($("sim-msg"), e.message, false)).then(() => {
  loadScenarios().then(loadGains).then(compareFromUrl).catch((e) => msg($("sim-msg"), e.message, false));
  loadStudies().catch((e) => msg($("study-msg"), e.message, false));
  connect();
});
