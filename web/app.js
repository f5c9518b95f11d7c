// Peregrine ground station page: telemetry websocket -> status, image plane, plots;
// REST API <- simulator controls and gains. Same origin; the access cookie rides along.
"use strict";

const $ = (id) => document.getElementById(id);
const W = (window.peregrine = { updates: 0, lastT: null, snap: null });

async function api(method, path, body) {
  const opts = { method, headers: {} };
  if (body !== undefined) {
    opts.headers["Content-Type"] = "application/json";
    opts.body = JSON.stringify(body);
  }
  const r = await fetch(path, opts);
  let data = null;
  try { data = await r.json(); } catch (e) { data = null; }
  if (!r.ok) {
    const detail = data && data.detail !== undefined ? data.detail : r.statusText;
    throw new Error(typeof detail === "string" ? detail : JSON.stringify(detail));
  }
  return data;
}

function msg(el, text, ok) {
  el.textContent = text;
  el.className = "msg " + (ok ? "ok" : "err");
}

// ------------------------------------------------------------------ plots
class Plot {
  constructor(canvas, title, unit, series, windowS = 15) {
    this.c = canvas; this.ctx = canvas.getContext("2d");
    this.title = title; this.unit = unit; this.series = series; this.windowS = windowS;
    this.data = series.map(() => []);
  }
  clear() { this.data = this.series.map(() => []); }
  setOverlay(rows) { this.overlay = rows; } // [[t, v] ...] per series, another sortie
  push(t, snap) {
    this.series.forEach((s, i) => {
      const v = s.get(snap);
      if (v !== null && v !== undefined && isFinite(v)) this.data[i].push([t, v]);
      const d = this.data[i];
      while (d.length && d[0][0] < t - this.windowS) d.shift();
    });
  }
  draw(tNow) {
    const { ctx, c } = this; const w = c.width, h = c.height;
    const L = 44, R = 8, T = 18, B = 20;
    ctx.clearRect(0, 0, w, h);
    let lo = Infinity, hi = -Infinity;
    for (const d of this.data) for (const [, v] of d) { lo = Math.min(lo, v); hi = Math.max(hi, v); }
    for (const d of this.overlay || []) for (const [t, v] of d) if (t >= tNow - this.windowS && t <= tNow + 1) { lo = Math.min(lo, v); hi = Math.max(hi, v); }
    if (!isFinite(lo)) { lo = 0; hi = 1; }
    if (hi - lo < 1e-6) { hi += 0.5; lo -= 0.5; }
    const pad = 0.08 * (hi - lo); lo -= pad; hi += pad;
    const t1 = Math.max(tNow, this.windowS), t0 = t1 - this.windowS;
    const X = (t) => L + ((t - t0) / (t1 - t0)) * (w - L - R);
    const Y = (v) => T + (1 - (v - lo) / (hi - lo)) * (h - T - B);
    ctx.strokeStyle = "#dde3e8"; ctx.fillStyle = "#5b6670"; ctx.font = "10px sans-serif";
    for (let k = 0; k <= 4; k++) {
      const v = lo + (k / 4) * (hi - lo), y = Y(v);
      ctx.beginPath(); ctx.moveTo(L, y); ctx.lineTo(w - R, y); ctx.stroke();
      ctx.fillText(v.toFixed(Math.abs(hi - lo) < 5 ? 2 : 1), 2, y + 3);
    }
    for (let s = Math.ceil(t0); s <= t1; s += 5) ctx.fillText(s + " s", X(s) - 8, h - 5);
    ctx.fillStyle = "#1d2329"; ctx.font = "bold 11px sans-serif";
    ctx.fillText(`${this.title} (${this.unit})`, L, 12);
    let lx = w - R;
    this.series.slice().reverse().forEach((s) => {
      ctx.font = "11px sans-serif"; const tw = ctx.measureText(s.label).width;
      lx -= tw + 18; ctx.fillStyle = s.color; ctx.fillRect(lx, 4, 10, 10);
      ctx.fillStyle = "#1d2329"; ctx.fillText(s.label, lx + 13, 13);
    });
    (this.overlay || []).forEach((d) => {
      const pts = d.filter(([t]) => t >= t0 && t <= t1); if (pts.length < 2) return;
      ctx.strokeStyle = "#9aa3ab"; ctx.setLineDash([4, 3]); ctx.lineWidth = 1.2; ctx.beginPath();
      pts.forEach(([t, v], k) => (k ? ctx.lineTo(X(t), Y(v)) : ctx.moveTo(X(t), Y(v))));
      ctx.stroke(); ctx.setLineDash([]); ctx.lineWidth = 1;
    });
    this.series.forEach((s, i) => {
      const d = this.data[i]; if (d.length < 2) return;
      ctx.strokeStyle = s.color; ctx.lineWidth = 1.5; ctx.beginPath();
      d.forEach(([t, v], k) => (k ? ctx.lineTo(X(t), Y(v)) : ctx.moveTo(X(t), Y(v))));
      ctx.stroke(); ctx.lineWidth = 1;
    });
  }
}

const plots = [
  new Plot($("plot-an"), "normal acceleration", "m/s²",
    [{ label: "a_n", color: "#d7263d", get: (s) => s.normal_accel_m_s2 }]),
  new Plot($("plot-speed"), "speed and normal velocity", "m/s",
    [{ label: "|v|", color: "#2f6fe0", get: (s) => s.speed_m_s },
     { label: "v normal to LOS", color: "#f08a24", get: (s) => s.normal_vel_m_s }]),
  new Plot($("plot-e"), "image error (DKF)", "px",
    [{ label: "e_x", color: "#19a35b", get: (s) => (s.e_est_px ? s.e_est_px[0] : null) },
     { label: "e_y", color: "#8e44ad", get: (s) => (s.e_est_px ? s.e_est_px[1] : null) }]),
  new Plot($("plot-range"), "range to target", "m",
    [{ label: "range", color: "#1d2329", get: (s) => s.range_m }]),
];

// ------------------------------------------------------------------ image plane
const img = { canvas: $("image"), frame: null, track: [], eyStart: null };
img.ctx = img.canvas.getContext("2d");

function drawImagePlane(s) {
  const { ctx, canvas } = img;
  const im = s.image || { w: 640, h: 480, f: 320, vfov_deg: 73.7 };
  if (canvas.width !== im.w || canvas.height !== im.h) { canvas.width = im.w; canvas.height = im.h; }
  const cu = im.w / 2, cv = im.h / 2;
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
  if (img.eyStart !== null) {
    const dq = Math.atan((s.k_a || 2) / 9.81);
    const dey = (cv * Math.tan(dq)) / Math.tan(((im.vfov_deg || 73.7) * Math.PI) / 360);
    for (const y of [cv + img.eyStart - dey, cv + img.eyStart + dey]) {
      ctx.beginPath(); ctx.moveTo(0, y); ctx.lineTo(im.w, y); ctx.stroke();
    }
  }
  ctx.setLineDash([]);
  ctx.strokeStyle = "#ffffff"; ctx.lineWidth = 2;
  ctx.beginPath(); ctx.moveTo(cu - 12, cv); ctx.lineTo(cu + 12, cv); ctx.moveTo(cu, cv - 12); ctx.lineTo(cu, cv + 12); ctx.stroke();
  if (img.track.length > 1) {
    ctx.strokeStyle = "#2f6fe0"; ctx.lineWidth = 2; ctx.beginPath();
    img.track.forEach(([x, y], k) => (k ? ctx.lineTo(cu + x, cv + y) : ctx.moveTo(cu + x, cv + y)));
    ctx.stroke();
  }
  if (s.e_raw_px) {
    ctx.strokeStyle = "#ff9f1c"; ctx.lineWidth = 2;
    ctx.strokeRect(cu + s.e_raw_px[0] - 7, cv + s.e_raw_px[1] - 7, 14, 14);
  }
  if (s.e_est_px) {
    ctx.strokeStyle = "#19c15b"; ctx.lineWidth = 2.5;
    ctx.beginPath(); ctx.arc(cu + s.e_est_px[0], cv + s.e_est_px[1], 9, 0, 2 * Math.PI); ctx.stroke();
  }
  ctx.lineWidth = 1;
}

// ------------------------------------------------------------------ status
function setBadge(id, text, cls) {
  const el = $(id); el.textContent = text; el.className = "badge" + (cls ? " " + cls : "");
}

function showStatus(st) {
  setBadge("st-state", st.state, st.state === "running" ? "ok" : st.state === "finished" ? "warn" : "");
  setBadge("st-scenario", `${st.scenario} · ${st.law} · seed ${st.seed} · ${st.camera} · ${st.speed}×`);
  setBadge("st-time", `t = ${Number(st.time_s).toFixed(2)} s`);
  if (st.outcome) setBadge("st-outcome", `${st.outcome} · miss ${Number(st.miss_m).toFixed(3)} m`, st.outcome === "HIT" ? "ok" : "bad");
  else setBadge("st-outcome", "no outcome");
  if (st.dkf) {
    const since = st.dkf.time_since_detection_s;
    const txt = !st.dkf.acquired ? "DKF waiting" : st.dkf.lost ? "DKF LOST" : `DKF ok · ${since === null ? "—" : (1000 * since).toFixed(0) + " ms"}`;
    setBadge("st-dkf", txt, st.dkf.lost && st.dkf.acquired ? "bad" : st.dkf.acquired ? "ok" : "");
  } else setBadge("st-dkf", "DKF —");
  setBadge("st-rate", `loop ${st.loop_rate_hz} Hz`);
  $("btn-pause").textContent = st.state === "paused" ? "Resume" : "Pause";
  showLive(st.live);
  showReplay(st.replay);
  loadOverlay(st.replay ? st.replay.compare : null);
  if (st.gains_applied_time_s !== null && st.gains_applied_time_s !== undefined)
    $("gains-applied").textContent = `last edit applied at t = ${Number(st.gains_applied_time_s).toFixed(2)} s`;
  if (st.gains_pending) $("gains-applied").textContent = st.live ? "edit sent: waiting for the vehicle's PARAM_VALUE" : "edit pending: next control tick";
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
  const pend = Object.keys(lv.params_pending), refused = Object.values(lv.params_refused);
  $("lv-params").textContent = `${lv.params_received}/${lv.params_total} read` + (pend.length ? ` · waiting for PARAM_VALUE: ${pend.join(", ")}` : "") + (refused.length ? ` · refused: ${refused.join("; ")}` : "");
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
// falling behind. window.peregrine.updates counts redraws that showed new data.
let pending = null;
let frameRequested = false;

function takeSnapshot(s) {
  W.received = (W.received || 0) + 1; W.snap = s;
  if (s.t !== undefined) {
    if (W.lastT !== null && s.t < W.lastT) { plots.forEach((p) => p.clear()); img.track = []; img.eyStart = null; img.frame = null; }
    W.lastT = s.t;
    if (s.frame_jpeg_b64) {
      const im = new Image();
      im.onload = () => { img.frame = im; };
      im.src = "data:image/jpeg;base64," + s.frame_jpeg_b64;
    }
    if (s.e_est_px) {
      img.track.push(s.e_est_px); if (img.track.length > 60) img.track.shift();
      if (img.eyStart === null) img.eyStart = s.e_est_px[1];
    }
    plots.forEach((p) => p.push(s.t, s));
  }
  pending = s;
  if (!frameRequested) { frameRequested = true; requestAnimationFrame(redraw); }
}

function redraw() {
  frameRequested = false;
  const s = pending; if (!s) return;
  pending = null;
  W.updates += 1; W.shownT = s.t;
  showStatus(s.status);
  drawImagePlane(s);
  plots.forEach((p) => p.draw(s.t === undefined ? 0 : s.t));
}

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
  $("rp-file").textContent = `${rp.file}${rp.status !== "ok" ? " (" + rp.status + ": replayed up to the damage)" : ""}${rp.compare ? " · compared with " + rp.compare : ""}`;
  const scrub = $("rp-scrub");
  scrub.max = rp.duration_s;
  if (!scrubbing) scrub.value = rp.t_s;
  $("rp-time").textContent = `${Number(rp.t_s).toFixed(2)} / ${Number(rp.duration_s).toFixed(2)} s`;
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

// a compared sortie's recorded series, drawn dashed under the live ones
let overlayName = null;
async function loadOverlay(name) {
  if (name === overlayName) return;
  overlayName = name;
  if (!name) { plots.forEach((p) => p.setOverlay(null)); return; }
  const s = await api("GET", `/api/logs/${encodeURIComponent(name)}/series`);
  const col = (vals) => s.t_s.map((t, i) => [t, vals[i]]).filter(([, v]) => v !== null && v !== undefined);
  plots[0].setOverlay([col(s.normal_accel_m_s2)]);
  plots[1].setOverlay([col(s.speed_m_s)]);
  plots[2].setOverlay([col(s.e_px.map((e) => (e ? e[0] : null))), col(s.e_px.map((e) => (e ? e[1] : null)))]);
  plots[3].setOverlay([col(s.range_m)]);
}

// ------------------------------------------------------------------ simulator controls
async function loadScenarios() {
  const list = await api("GET", "/api/scenarios");
  const sel = $("scenario"); sel.innerHTML = "";
  for (const s of list) {
    const o = document.createElement("option"); o.value = s.name; o.textContent = `${s.name} (${s.motion})`; o.title = s.description;
    sel.appendChild(o);
  }
  sel.value = "cv-top-to-bottom";
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

$("btn-start").onclick = async () => {
  const body = { law: $("law").value, seed: parseInt($("seed").value || "0", 10), camera: $("camera").value, speed: $("speed").value };
  if ($("use-toml").checked) body.toml = $("toml").value; else body.scenario = $("scenario").value;
  if ($("wind-override").checked) {
    body.wind_mean_m_s = ["wind-x", "wind-y", "wind-z"].map((id) => parseFloat($(id).value || "0"));
    body.gust_m_s = parseFloat($("gust").value || "0");
  }
  try { showStatus(await api("POST", "/api/sortie/start", body)); msg($("sim-msg"), "started", true); await loadGains(); }
  catch (e) { msg($("sim-msg"), e.message, false); }
};
$("btn-pause").onclick = async () => {
  const path = $("btn-pause").textContent === "Resume" ? "/api/sortie/resume" : "/api/sortie/pause";
  try { showStatus(await api("POST", path)); } catch (e) { msg($("sim-msg"), e.message, false); }
};
$("btn-step").onclick = async () => { try { showStatus(await api("POST", "/api/sortie/step")); } catch (e) { msg($("sim-msg"), e.message, false); } };
$("btn-reset").onclick = async () => { try { showStatus(await api("POST", "/api/sortie/reset")); msg($("sim-msg"), "reset", true); } catch (e) { msg($("sim-msg"), e.message, false); } };
$("speed").onchange = async () => { try { await api("PUT", "/api/sortie/speed", { speed: $("speed").value }); } catch (e) { msg($("sim-msg"), e.message, false); } };

// ------------------------------------------------------------------ gains
let gainValues = {};
async function loadGains() {
  const g = await api("GET", "/api/gains");
  gainValues = g.values;
  const tb = document.querySelector("#gains tbody"); tb.innerHTML = "";
  for (const s of g.specs) {
    const tr = document.createElement("tr"); tr.title = s.meaning;
    tr.innerHTML = `<td>${s.name}</td><td><input data-gain="${s.name}" value="${g.values[s.name]}"></td><td>${s.unit}</td><td>[${s.min}, ${s.max}]</td><td>${s.default}</td>`;
    tb.appendChild(tr);
  }
  tb.querySelectorAll("input").forEach((inp) => {
    inp.oninput = () => inp.classList.toggle("changed", inp.value !== String(gainValues[inp.dataset.gain]));
  });
  const names = await api("GET", "/api/gainsets");
  const sel = $("gainsets"); sel.innerHTML = "";
  for (const n of names) { const o = document.createElement("option"); o.value = n; o.textContent = n; sel.appendChild(o); }
}

$("btn-apply-gains").onclick = async () => {
  const changes = {};
  document.querySelectorAll("#gains input").forEach((inp) => {
    inp.classList.remove("bad");
    if (inp.value !== String(gainValues[inp.dataset.gain])) {
      const v = Number(inp.value);
      changes[inp.dataset.gain] = inp.value.trim() === "" || !isFinite(v) ? inp.value : v;
    }
  });
  if (!Object.keys(changes).length) { msg($("gains-msg"), "nothing changed", true); return; }
  try {
    await api("PUT", "/api/gains", changes);
    msg($("gains-msg"), "applied: " + Object.entries(changes).map(([k, v]) => `${k} = ${v}`).join(", "), true);
    await loadGains();
  } catch (e) {
    msg($("gains-msg"), "refused: " + e.message + " (running values unchanged)", false);
    for (const k of Object.keys(changes)) { const el = document.querySelector(`#gains input[data-gain="${k}"]`); if (el) el.classList.add("bad"); }
  }
};
$("btn-reset-gains").onclick = async () => { try { await api("POST", "/api/gains/reset"); await loadGains(); msg($("gains-msg"), "defaults restored", true); } catch (e) { msg($("gains-msg"), e.message, false); } };
$("btn-save-gainset").onclick = async () => {
  const name = $("gainset-name").value.trim();
  try { await api("PUT", "/api/gainsets/" + encodeURIComponent(name)); await loadGains(); msg($("gains-msg"), `saved '${name}'`, true); }
  catch (e) { msg($("gains-msg"), e.message, false); }
};
$("btn-load-gainset").onclick = async () => {
  const name = $("gainsets").value; if (!name) return;
  try { await api("POST", `/api/gainsets/${encodeURIComponent(name)}/load`); await loadGains(); msg($("gains-msg"), `loaded '${name}'`, true); }
  catch (e) { msg($("gains-msg"), e.message, false); }
};

// The 3D view only in a visible tab: a hidden one drops its viser connection (viser replays
// the whole scene when it reconnects), so background tabs cost the machine almost nothing.
function syncSceneToVisibility() {
  const frame = $("viser");
  const visible = document.visibilityState === "visible";
  if (visible && frame.dataset.live !== "1") { frame.src = "/viser/"; frame.dataset.live = "1"; }
  if (!visible && frame.dataset.live === "1") { frame.src = "about:blank"; frame.dataset.live = "0"; }
}
document.addEventListener("visibilitychange", syncSceneToVisibility);
syncSceneToVisibility();

loadScenarios().then(loadGains).catch((e) => msg($("sim-msg"), e.message, false));
connect();
