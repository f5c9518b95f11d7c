// What every page of the ground station shares (loaded first, a classic script: its names are
// the pages' globals): element lookup, HTML escaping, the REST call with the server's refusal
// as the error's message, a message line, and the colours of sorties shown together.
"use strict";
const $ = (id) => document.getElementById(id);
const esc = (s) => String(s).replace(/[&<>"]/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;" }[c]));

// fetch with JSON in and out; a refusal throws an Error whose message is the server's sentence
// (``detail``) and whose ``data`` is the whole answer (e.g. {refused: {name: why}} of a gains edit)
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
    const err = new Error(typeof detail === "string" ? detail : JSON.stringify(detail));
    err.data = data;
    throw err;
  }
  return data;
}

function msg(el, text, ok) {
  el.textContent = text;
  el.className = "msg " + (ok ? "ok" : "err");
}

// a number in the one rounding rule (web/format.js), a text as it is, nothing as "—"
const fmtCell = (v) => (typeof v === "number" ? window.fmtNum(v) : v === null || v === undefined ? "—" : v);

// one colour per sortie of an overlay (up to the server's OVERLAY_MAX, 20)
const SORTIE_COLORS = ["#2f6fe0", "#d7263d", "#19a35b", "#f08a24", "#8e44ad", "#00a8a8", "#b8860b", "#e0529c", "#6b8e23", "#1d2329",
  "#7f8c8d", "#c0392b", "#16a085", "#d35400", "#2c3e50", "#9b59b6", "#27ae60", "#e67e22", "#34495e", "#a0522d"];

// the page's own message line (#msg)
function say(text, ok) { msg($("msg"), text, ok); }
