// Several recorded sorties on one page (?names=a,b,...; up to 20): the dashboard's plots with
// one colour per sortie, aligned on the intercept or on the start, their trajectories relative
// to the target in 3D, and a table of outcome, miss, intercept time and only the gains that differ.
// A scrub moves one cursor through every plot and trajectory. Clicking a sortie opens it in
// the dashboard; Re-fly opens the Sorties page's re-fly form prefilled with its gains.
"use strict";
const fmt = window.fmtNum;
const COLORS = SORTIE_COLORS; // web/common.js
const PLOTS = [
  { title: "normal acceleration (m/s²)", key: "normal_accel_m_s2" },
  { title: "speed (m/s)", key: "speed_m_s" },
  { title: "image error e_y (DKF, px)", key: "e_y_px" },
  { title: "range to target (m)", key: "range_m" },
];
const O = (window.peregrine = { sorties: [], plots: [], openedMs: null, drawn: 0, cursor: 0 });

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
      title: p.title, width: Math.max(grid.clientWidth / 2 - 10, 300), height: 200, series, padding: [null, 16, null, null],
      scales: { x: { time: false, auto: false, range: () => [lo, hi] } },
      axes: [{ label: series[0].label, labelSize: 16, size: 34 }, { size: 52, values: (u, vals) => vals.map(fmt) }],
      // the scrub moves uPlot's own cursor line (an element): no plot is redrawn for it
      cursor: { sync: { key: "overlay" }, points: { show: false }, drag: { x: false, y: false } }, legend: { show: false },
    }, plotData(p.key), box);
    return u;
  });
  const sc = $("ov-scrub"); sc.min = lo; sc.max = hi; sc.step = (hi - lo) / 1000; sc.value = O.cursor = Math.min(Math.max(O.cursor, lo), hi);
}

// each vehicle's trajectory relative to its target, in 3D (web/relview.js)
const rel = (O.rel = new RelView($("ov-rel"), () => scrubTo(O.cursor)));
function drawRel() {
  rel.draw(O.sorties.map((s, i) => {
    const t = O.cursor + shift(s);
    let j = s.t_s.findIndex((x) => x >= t);
    if (j < 0) j = s.t_s.length - 1;
    return s.rel_m[j] ? [COLORS[i], s.rel_m[j]] : null;
  }));
}
document.querySelectorAll("[data-relview]").forEach((b) => { b.onclick = () => rel.setView(b.dataset.relview); });

let frame = null;
function scrubTo(t) {
  O.cursor = t;
  if (frame) return;
  frame = requestAnimationFrame(() => {
    frame = null;
    for (const u of O.plots) u.setCursor({ left: u.valToPos(O.cursor, "x"), top: u.bbox.height / devicePixelRatio / 2 }, false);
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
    O.fetchMs = performance.now() - t0; // the request: the server reads the sorties
    $("ov-count").textContent = `${O.sorties.length} sorties`;
    table(); buildPlots();
    rel.setTracks(O.sorties.map((s, i) => ({ color: COLORS[i], points: s.rel_m })));
    scrubTo(0);
    await new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r)));
    O.openedMs = performance.now() - t0;
  } catch (e) { say(e.message, false); }
})();
