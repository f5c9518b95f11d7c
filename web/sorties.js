// Recorded sorties: list (sortable, filterable), open in the dashboard, compare two,
// download, delete (confirmed), re-fly with another law.
"use strict";
let rows = [];
let sortKey = "name", sortDir = -1;
const OVERLAY_MAX = 20; // as the server's
const selected = new Set(); // sorties picked for the overlay

const fmt = fmtCell; // web/common.js

const W = (window.peregrine = { shown: [] });
function showSelected() {
  $("ov-go").textContent = `Overlay selected (${selected.size})`;
  $("ov-go").disabled = selected.size < 1;
}
function render() {
  const f = $("filter").value.trim().toLowerCase();
  const shown = rows.filter((r) => !f || [r.name, r.scenario, r.law, r.camera, r.seed, r.outcome, r.status, r.reflown_from].join(" ").toLowerCase().includes(f));
  shown.sort((a, b) => {
    const x = a[sortKey] ?? "", y = b[sortKey] ?? "";
    return (x > y ? 1 : x < y ? -1 : 0) * sortDir;
  });
  const tb = document.querySelector("#logs tbody");
  tb.innerHTML = shown.map((r) => {
    const n = encodeURIComponent(r.name);
    const ok = r.status === "ok";
    return `<tr data-name="${esc(r.name)}">
      <td title="${esc(r.name)}">${esc(r.recorded_at_utc || r.name.slice(0, 16))}</td><td>${esc(r.scenario || "—")}</td><td>${esc(r.law || "—")}</td>
      <td>${esc(r.camera || "—")}</td><td>${fmt(r.seed)}</td>
      <td>${esc(r.outcome || "—")}</td><td>${fmt(r.miss_m)}</td><td>${fmt(r.intercept_time_s)}</td><td>${fmt(r.duration_s)}</td>
      <td class="lineage">${r.reflown_from ? "re-flown from " + esc(r.reflown_from) : ""}</td>
      <td class="${ok ? "" : "bad"}" title="${esc(r.problem || "")}">${esc(r.status)}</td><td>${(r.size_bytes / 1024).toFixed(0)} kB</td>
      <td>${r.status === "not_mcap" ? "" : `<button data-act="open">Open</button> <button data-act="compare">Compare</button> <button data-act="refly">Re-fly</button>`}
          <a href="/api/logs/${n}/file" download>Download</a> <button data-act="delete">Delete</button>
          ${r.status === "not_mcap" ? "" : `<label title="overlay it with others"><input type="checkbox" data-sel ${selected.has(r.name) ? "checked" : ""}> overlay</label>`}</td></tr>`;
  }).join("");
  $("count").textContent = `${shown.length} of ${rows.length} sorties`;
  W.shown = shown.map((r) => r.name);
  showSelected();
  const empty = $("empty");
  empty.hidden = shown.length > 0;
  empty.textContent = rows.length === 0
    ? "No recorded sorties yet. Every sortie flown from the dashboard is recorded here: go to the dashboard and press Start."
    : `No sortie matches "${$("filter").value}".`;
}

// the log folder and its subfolders (a campaign's `--log logs/NAME`): the page browses them
// without a server restart; the server names nothing outside the log folder
async function loadFolders() {
  const folders = await api("GET", "/api/logfolders");
  const sel = $("folder"), want = new URLSearchParams(location.search).get("folder") || sel.value || "";
  sel.innerHTML = "";
  for (const f of folders) { const o = document.createElement("option"); o.value = f; o.textContent = f ? f + "/" : "(top)"; sel.appendChild(o); }
  sel.value = folders.includes(want) ? want : "";
}
let loads = 0; // a listing that comes back after a later one (another folder) is dropped
async function load() {
  const folder = $("folder").value || "", mine = ++loads;
  const got = await api("GET", "/api/logs?folder=" + encodeURIComponent(folder));
  if (mine !== loads) return;
  rows = got;
  $("folder-shown").textContent = `(logs/${folder ? folder + "/" : ""})`;
  render();
}
$("folder").onchange = () => {
  const u = new URL(location.href);
  if ($("folder").value) u.searchParams.set("folder", $("folder").value); else u.searchParams.delete("folder");
  history.replaceState(null, "", u);
  load().catch((e) => say(e.message, false));
};

document.querySelectorAll("#logs th[data-k]").forEach((th) => {
  th.style.cursor = "pointer";
  th.onclick = () => { const k = th.dataset.k; sortDir = sortKey === k ? -sortDir : 1; sortKey = k; render(); };
});
$("filter").oninput = render;
document.querySelector("#logs tbody").addEventListener("change", (ev) => {
  const box = ev.target.closest("input[data-sel]"); if (!box) return;
  const name = box.closest("tr").dataset.name;
  if (box.checked && selected.size >= OVERLAY_MAX) { box.checked = false; say(`at most ${OVERLAY_MAX} sorties at once`, false); return; }
  if (box.checked) selected.add(name); else selected.delete(name);
  // the server reads it for the overlay now, while more are picked (it keeps what it read)
  if (box.checked) fetch("/api/overlay?names=" + encodeURIComponent(name)).catch(() => {});
  showSelected();
});
$("ov-shown").onclick = () => {
  for (const n of W.shown) { if (selected.size >= OVERLAY_MAX) break; if (rows.find((r) => r.name === n && r.status !== "not_mcap")) selected.add(n); }
  if (W.shown.length > OVERLAY_MAX) say(`the first ${OVERLAY_MAX} shown are selected`, true);
  if (selected.size) fetch("/api/overlay?names=" + encodeURIComponent([...selected].join(","))).catch(() => {}); // read ahead
  render();
};
$("ov-clear").onclick = () => { selected.clear(); render(); };
$("ov-go").onclick = () => { location.href = "/overlay?names=" + encodeURIComponent([...selected].join(",")); };
document.querySelector("#logs tbody").onclick = async (ev) => {
  const btn = ev.target.closest("button"); if (!btn) return;
  const name = btn.closest("tr").dataset.name;
  try {
    if (btn.dataset.act === "open") { await api("POST", "/api/replay/open", { name }); location.href = "/"; }
    else if (btn.dataset.act === "compare") { await api("POST", "/api/replay/compare", { name }); say(`overlaying ${name} in the dashboard`, true); location.href = "/?compare=" + encodeURIComponent(name); }
    else if (btn.dataset.act === "refly") await reflyForm(name);
    else if (btn.dataset.act === "delete") {
      if (!window.confirm(`Delete ${name}? This cannot be undone.`)) return;
      await api("DELETE", `/api/logs/${encodeURIComponent(name)}?confirm=${encodeURIComponent(name)}`);
      say(`deleted ${name}`, true); await load();
    }
  } catch (e) { say(e.message, false); }
};
// Re-fly: a form prefilled with the gains the sortie flew; the changed ones fly with the law
// and speed chosen above (the re-fly's gains are that sortie's only).
let reflyOf = null, reflyGains = {};
async function reflyForm(name) {
  const [info, g] = await Promise.all([api("GET", "/api/logs/" + encodeURIComponent(name)), api("GET", "/api/gains")]);
  let recorded = {};
  try { recorded = JSON.parse(((info.metadata || {}).sortie || {}).gains || "{}"); } catch (e) { recorded = {}; }
  reflyOf = name; reflyGains = {};
  const rows = [];
  let group = null;
  for (const s of g.specs) {
    const v = s.name in recorded ? recorded[s.name] : s.default;
    reflyGains[s.name] = v;
    if (s.group !== group) { group = s.group; rows.push(`<tr class="group"><th colspan="5">${esc(group)}</th></tr>`); }
    rows.push(`<tr><td>${esc(s.name)}</td><td><input data-gain="${esc(s.name)}" value="${v}" size="9"></td><td>${esc(s.unit === "-" ? "" : s.unit.replace("^2", "²"))}</td><td>${esc(s.meaning)}</td><td>${s.min} to ${s.max}</td></tr>`);
  }
  document.querySelector("#refly-gains tbody").innerHTML = rows.join("");
  $("refly-name").textContent = name;
  $("refly-form").hidden = false;
  $("refly-form").scrollIntoView({ block: "nearest" });
}
$("refly-cancel").onclick = () => { $("refly-form").hidden = true; reflyOf = null; };
$("refly-go").onclick = async () => {
  if (!reflyOf) return;
  const gains = {};
  document.querySelectorAll("#refly-gains input[data-gain]").forEach((inp) => {
    if (inp.value !== String(reflyGains[inp.dataset.gain])) { const v = Number(inp.value); gains[inp.dataset.gain] = inp.value.trim() === "" || !isFinite(v) ? inp.value : v; }
  });
  try {
    await api("POST", `/api/logs/${encodeURIComponent(reflyOf)}/refly`, { law: $("refly-law").value, speed: $("refly-speed").value, gains });
    location.href = "/?compare=" + encodeURIComponent(reflyOf);
  } catch (e) { say(e.message, false); }
};
loadFolders().then(load).then(() => { // ?refly=NAME (from the overlay page): its form open
  const n = new URLSearchParams(location.search).get("refly");
  if (n) return reflyForm(n);
}).catch((e) => say(e.message, false));
