// The gain studies `groundstation tune` stored: trials, best-so-far plot, Fly a trial.
// A part of the dashboard page (web/app.js lists them); the parts share the page's globals.
"use strict";

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
