// Replay of a recorded sortie: play, pause, scrub, closest approach, and ?compare=.
// A part of the dashboard page (web/app.js lists them); the parts share the page's globals.
"use strict";

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
