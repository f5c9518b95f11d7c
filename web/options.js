// Option lists of the page's <select data-options="..."> elements, from GET /api/meta: the
// laws, camera modes and speeds are declared once on the server (onboard/enums.py ...), never
// here. A select keeps the value it had if the new list still has it, and otherwise starts on
// the server's default (the law flown when none is named, ...).
"use strict";
window.peregrineMeta = (async () => {
  const r = await fetch("/api/meta");
  if (!r.ok) throw new Error(`GET /api/meta: ${r.status}`);
  const meta = await r.json();
  const label = { speeds: (v) => (v === "max" ? "max" : `${v}×`) };
  for (const sel of document.querySelectorAll("select[data-options]")) {
    const key = sel.dataset.options;
    const keep = sel.value;
    sel.replaceChildren(...(meta[key] || []).map((v) => new Option((label[key] || String)(v), v)));
    const start = keep && meta[key] && meta[key].includes(keep) ? keep : (meta.defaults || {})[key];
    if (start !== undefined) sel.value = start;
  }
  return meta;
})();
