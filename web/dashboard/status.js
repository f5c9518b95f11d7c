// The header, the recording banner, the controls in force and the live vehicle's table, from
// each status.
// A part of the dashboard page (web/app.js lists them); the parts share the page's globals.
"use strict";

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
