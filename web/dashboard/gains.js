// The gains panel: grouped gains, edits, Apply, resets and named gain sets.
// A part of the dashboard page (web/app.js lists them); the parts share the page's globals.
"use strict";

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
