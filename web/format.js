// The one rule for numbers shown to the operator (as groundstation/app/numbers.py): at most 4
// significant digits, halves away from zero, no trailing zeros. 0.006525 -> "0.006525",
// 12.3456 -> "12.35", 3 -> "3".
"use strict";
window.fmtNum = (v) => {
  if (v === null || v === undefined || v === "") return "—";
  const x = Number(v);
  if (!isFinite(x)) return String(x);
  if (x === 0) return "0";
  const s = String(Number(x.toPrecision(4)));
  if (!/e/.test(s)) return s;
  // very small or large: plain digits, as the server writes them
  const e = Math.floor(Math.log10(Math.abs(Number(s))));
  return e < 0 ? Number(s).toFixed(Math.min(3 - e, 100)).replace(/0+$/, "").replace(/\.$/, "") : BigInt(Math.round(Number(s))).toString();
};
