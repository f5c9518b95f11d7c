// The simulator's controls: scenario, law, seed, camera, wind, Start, Pause, Step, Reset, speed.
// A part of the dashboard page (web/app.js lists them); the parts share the page's globals.
"use strict";

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
