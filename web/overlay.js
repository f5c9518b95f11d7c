// Several recorded sorties on one page (?names=a,b,...; up to 20): the dashboard's plots with
// one colour per sortie, aligned on the intercept or on the start, their trajectories relative
// to the target, and a table of outcome, miss, intercept time and only the gains that differ.
// A scrub moves one cursor through every plot and trajectory. Clicking a sortie opens it in
// the dashboard; Re-fly opens the Sorties page's re-fly form prefilled with its gains.
"use strict";
const $ = (id) => document.getElementById(id);
const esc = (s) => String(s).replace(/[&<>"]/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;" }[c]));
const fmt = window.fmtNum;
const COLORS = ["#2f6fe0", "#d7263d", "#19a35b", "#f08a24", "#8e44ad", "#00a8a8", "#b8860b", "#e0529c", "#6b8e23", "#1d2329",
  "#7f8c8d", "#c0392b", "#16a085", "#d35400", "#2c3e50", "#9b59b6", "#27ae60", "#e67e22", "#34495e", "#a0522d"];
const PLOTS = [
  { title: "normal acceleration (m/s²)", key: "normal_accel_m_s2" },
  { title: "speed (m/s)", key: "speed_m_s" },
  { title: "image error e_y (DKF, px)", key: "e_y_px" },
  { title: "range to target (m)", key: "range_m" },
];
const O = (window.peregrine = { sorties: [], plots: [], openedMs: null, drawn: 0, cursor: 0 });

async function api(method, path, body) {
  const opts = { method, headers: {} };
  if (body !== undefined) { opts.headers["Content-Type"] = "application/json"; opts.body = JSON.stringify(body); }
  const r = await fetch(path, opts);
  let data = null; try { data = await r.json(); } catch (e) { data = null; }
  if (!r.ok) throw new Error(data && data.detail ? (typeof data.detail === "string" ? data.detail : JSON.stringify(data.detail)) : r.statusText);
  return data;
}
function say(text, ok) { $("msg").textContent = text; $("msg").className = "msg " + (ok ? "ok" : "err"); }

const shift = (s) => ($("ov-align").value === "intercept" ? s.intercept_time_s : 0);
function span() {
  let lo = Infinity, hi = -Infinity;
  for (const s of O.sorties) { const d = shift(s); lo = Math.min(lo, -d); hi = Math.max(hi, s.duration_s - d); }
  return [lo, hi];
}

// the gains whose values are not the same in every sortie
function differingGains() {
  const keys = new Set();
  for (const s of O.sorties) for (const k of Object.keys(s.gains || {})) keys.add(k);
  return [...keys].filter((k) => new Set(O.sorties.map((s) => (s.gains || {})[k])).size > 1).sort();
}

function table() {
  const diff = differingGains();
  $("ov-gains-head").textContent = diff.length ? "gains that differ" : "gains (the same in all)";
  document.querySelector("#ov-table tbody").innerHTML = O.sorties.map((s, i) => `<tr data-name="${esc(s.file)}">
    <td><i class="sw" style="background:${COLORS[i]}"></i></td><td><a href="#" data-act="open" title="open in the dashboard">${esc(s.file)}</a></td>
    <td>${esc(s.scenario || "—")}</td><td>${esc(s.law || "—")}</td><td>${fmt(s.seed)}</td><td>${esc(s.outcome || "—")}</td>
    <td>${fmt(s.miss_m)}</td><td>${fmt(s.intercept_time_s)}</td>
    <td class="gains">${esc(diff.map((k) => `${k} ${fmt((s.gains || {})[k])}`).join(", "))}</td>
    <td><button data-act="refly" title="re-fly it with edited gains">Re-fly</button></td></tr>`).join("");
}

function plotData(key) {
  const parts = O.sorties.map((s) => { const d = shift(s); return [s.t_s.map((t) => t - d), s.columns[key]]; });
  return uPlot.join(parts);
}
function buildPlots() {
  for (const u of O.plots) u.destroy();
  const grid = $("ov-plots"); grid.innerHTML = "";
  const [lo, hi] = span();
  O.plots = PLOTS.map((p) => {
    const box = document.createElement("div"); box.className = "plot"; grid.appendChild(box);
    const series = [{ label: $("ov-align").value === "intercept" ? "t − t_intercept (s)" : "t (s)", value: (u, v) => fmt(v) }]
      .concat(O.sorties.map((s, i) => ({ label: `#${i + 1}`, stroke: COLORS[i], width: 1.3, spanGaps: true, value: (u, v) => fmt(v) })));
    const u = new uPlot({
      title: p.title, width: Math.max(grid.clientWidth / 2 - 10, 300), height: 200, series,
      scales: { x: { time: false, auto: false, range: () => [lo, hi] } },
      axes: [{ label: series[0].label, labelSize: 16, size: 34 }, { size: 52, values: (u, vals) => vals.map(fmt) }],
      cursor: { sync: { key: "overlay" } }, legend: { show: false },
      hooks: { draw: [(u) => { const x = u.valToPos(O.cursor, "x", true); u.ctx.save(); u.ctx.strokeStyle = "#d7263d"; u.ctx.lineWidth = 2;
        u.ctx.beginPath(); u.ctx.moveTo(x, u.bbox.top); u.ctx.lineTo(x, u.bbox.top + u.bbox.height); u.ctx.stroke(); u.ctx.restore(); }] },
    }, plotData(p.key), box);
    return u;
  });
  const sc = $("ov-scrub"); sc.min = lo; sc.max = hi; sc.step = (hi - lo) / 1000; sc.value = O.cursor = Math.min(Math.max(O.cursor, lo), hi);
}

// plan (east, north) and side (north, up) views of each vehicle relative to its target
function drawRel() {
  const cv = $("ov-rel"), ctx = cv.getContext("2d"), W = cv.width / 2, H = cv.height;
  ctx.clearRect(0, 0, cv.width, cv.height);
  let m = 1;
  for (const s of O.sorties) for (const r of s.rel_m) m = Math.max(m, Math.abs(r[0]), Math.abs(r[1]), Math.abs(r[2]));
  const views = [[0, 1, "plan: east → , north ↑"], [1, 2, "side: north → , up ↑"]];
  views.forEach(([a, b, name], k) => {
    const ox = k * W + W / 2, oy = H / 2, sc = (Math.min(W, H) / 2 - 16) / m;
    ctx.strokeStyle = "#dde3e8"; ctx.beginPath(); ctx.moveTo(k * W + 8, oy); ctx.lineTo(k * W + W - 8, oy); ctx.moveTo(ox, 8); ctx.lineTo(ox, H - 8); ctx.stroke();
    ctx.fillStyle = "#47525d"; ctx.font = "12px sans-serif"; ctx.fillText(`${name} · ${fmt(m)} m to the edge`, k * W + 8, 14);
    ctx.fillStyle = "#d7263d"; ctx.beginPath(); ctx.arc(ox, oy, 4, 0, 2 * Math.PI); ctx.fill(); // the target
    O.sorties.forEach((s, i) => {
      ctx.strokeStyle = COLORS[i]; ctx.lineWidth = 1.3; ctx.beginPath();
      s.rel_m.forEach((r, j) => (j ? ctx.lineTo(ox + r[a] * sc, oy - r[b] * sc) : ctx.moveTo(ox + r[a] * sc, oy - r[b] * sc)));
      ctx.stroke();
      const t = O.cursor + shift(s); let j = s.t_s.findIndex((x) => x >= t); if (j < 0) j = s.t_s.length - 1;
      const r = s.rel_m[j]; if (!r) return;
      ctx.fillStyle = COLORS[i]; ctx.beginPath(); ctx.arc(ox + r[a] * sc, oy - r[b] * sc, 4, 0, 2 * Math.PI); ctx.fill();
    });
  });
}

let frame = null;
function scrubTo(t) {
  O.cursor = t;
  if (frame) return;
  frame = requestAnimationFrame(() => {
    frame = null;
    for (const u of O.plots) u.redraw(false, false);
    drawRel();
    $("ov-time").textContent = `${$("ov-align").value === "intercept" ? "t − t_intercept" : "t"} = ${fmt(O.cursor)} s`;
    O.drawn += 1;
  });
}
$("ov-scrub").oninput = () => scrubTo(parseFloat($("ov-scrub").value));
$("ov-align").onchange = () => { buildPlots(); scrubTo(O.cursor); };
document.querySelector("#ov-table tbody").onclick = async (ev) => {
  const el = ev.target.closest("[data-act]"); if (!el) return;
  ev.preventDefault();
  const name = el.closest("tr").dataset.name;
  try {
    if (el.dataset.act === "open") { await api("POST", "/api/replay/open", { name }); location.href = "/"; }
    else location.href = "/sorties?refly=" + encodeURIComponent(name);
  } catch (e) { say(e.message, false); }
};

(async () => {
  const t0 = performance.now();
  const names = (new URLSearchParams(location.search).get("names") || "").split(",").filter(Boolean);
  try {
    O.sorties = await api("GET", "/api/overlay?names=" + encodeURIComponent(names.join(",")));
    $("ov-count").textContent = `${O.sorties.length} sorties`;
    table(); buildPlots(); scrubTo(0);
    await new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r)));
    O.openedMs = performance.now() - t0;
  } catch (e) { say(e.message, false); }
})();
