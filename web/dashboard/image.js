// The image plane: the camera frame, the FOV-holding band, the detection, the estimate, the
// recent track and the end marker.
// A part of the dashboard page (web/app.js lists them); the parts share the page's globals.
"use strict";

const img = { canvas: $("image"), frame: null, asked: 0, seq: 0, decoding: 0 };
img.ctx = img.canvas.getContext("2d");

function drawImagePlane(s) {
  const { ctx, canvas } = img;
  const im = s.image || { w: 640, h: 480, f: 320, vfov_deg: 73.7 };
  if (canvas.width !== im.w || canvas.height !== im.h) { canvas.width = im.w; canvas.height = im.h; }
  const cu = im.w / 2, cv = im.h / 2;
  W.imageShown = [s.t, img.frame ? img.frame.frameT : null]; // the time shown and its camera frame's
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
  // the band is centred where the target sits once the estimate has settled: the median e_y
  // of the sortie's estimates after their first TRANSIENT_S (not the first, transient one)
  const c = bandCentre();
  W.band = null;
  if (c !== null) {
    const dq = Math.atan((s.k_a || 2) / 9.81);
    const dey = (cv * Math.tan(dq)) / Math.tan(((im.vfov_deg || 73.7) * Math.PI) / 360);
    W.band = { centre: c, half: dey };
    for (const y of [cv + c - dey, cv + c + dey]) {
      ctx.beginPath(); ctx.moveTo(0, y); ctx.lineTo(im.w, y); ctx.stroke();
    }
  }
  ctx.setLineDash([]);
  ctx.strokeStyle = "#ffffff"; ctx.lineWidth = 2;
  ctx.beginPath(); ctx.moveTo(cu - 12, cv); ctx.lineTo(cu + 12, cv); ctx.moveTo(cu, cv - 12); ctx.lineTo(cu, cv + 12); ctx.stroke();
  const track = recentTrack();
  W.trackPoints = track.length;
  if (track.length > 1) {
    ctx.strokeStyle = "#2f6fe0"; ctx.lineWidth = 2; ctx.beginPath();
    track.forEach(([x, y], k) => (k ? ctx.lineTo(cu + x, cv + y) : ctx.moveTo(cu + x, cv + y)));
    ctx.stroke();
  }
  // markers are outlines drawn clear of the balloon: sized from its apparent diameter
  const dpx = s.range_m && s.target && s.target.diameter_m ? (im.f * s.target.diameter_m) / s.range_m : 0;
  // (at most MARKER_MAX_PX: near the end the balloon fills the image, the marker must show)
  const r = Math.min(Math.max(9, dpx / 2 + 6), MARKER_MAX_PX);
  if (s.e_raw_px) { // corner brackets: the balloon shows between them
    const x = cu + s.e_raw_px[0], y = cv + s.e_raw_px[1], a = r + 3, l = Math.max(5, a / 2);
    ctx.strokeStyle = "#ff9f1c"; ctx.lineWidth = 2; ctx.beginPath();
    for (const [sx, sy] of [[-1, -1], [1, -1], [1, 1], [-1, 1]]) {
      ctx.moveTo(x + sx * a, y + sy * (a - l)); ctx.lineTo(x + sx * a, y + sy * a); ctx.lineTo(x + sx * (a - l), y + sy * a);
    }
    ctx.stroke();
  }
  W.edgeArrow = null; W.endMarker = null; W.estMarker = null;
  const st = s.status || {};
  const ended = !s.e_est_px && (st.state === "finished" || (st.replay && st.outcome));
  const last = ended ? (track.length ? track[track.length - 1] : lastEstimate()) : null;
  if (last) {
    // the sortie has ended and the loop no longer estimates (after the pass it flies on while
    // it recovers): where the target was last seen
    const [ex, ey] = last, x = cu + ex, y = cv + ey;
    ctx.save(); ctx.setLineDash([4, 3]); ctx.strokeStyle = "#19c15b"; ctx.lineWidth = 2.5;
    ctx.beginPath(); ctx.arc(x, y, r, 0, 2 * Math.PI); ctx.stroke(); ctx.restore();
    ctx.fillStyle = "#0b5e2c"; ctx.font = "bold 12px sans-serif";
    ctx.fillText(`last estimate · ${st.outcome || "ended"}`, Math.min(Math.max(x + r + 4, 4), im.w - 150), Math.min(Math.max(y + 4, 14), im.h - 6));
    W.endMarker = { x, y };
  }
  if (s.e_est_px) {
    const x = cu + s.e_est_px[0], y = cv + s.e_est_px[1];
    if (x >= 0 && x <= im.w && y >= 0 && y <= im.h) {
      ctx.strokeStyle = "#19c15b"; ctx.lineWidth = 2.5;
      ctx.beginPath(); ctx.arc(x, y, r, 0, 2 * Math.PI); ctx.stroke();
      W.estMarker = { x, y, r };
    } else drawEdgeArrow(ctx, im, cu, cv, x, y);
  }
  ctx.lineWidth = 1;
}

// the sortie's last estimated image error (px), or null
function lastEstimate() {
  const ex = colOf(PV.own, "e_x_px"), ey = colOf(PV.own, "e_y_px");
  for (let i = Math.min(ex.length, ey.length) - 1; i >= 0; i--) if (ex[i] !== null && ey[i] !== null) return [ex[i], ey[i]];
  return null;
}

const TRANSIENT_S = 1.0, TRACK_S = 1.5, MARKER_MAX_PX = 40;
let bandCache = { n: -1, src: null, c: null };
function bandCentre() {
  const src = PV.own, ys = (src.columns && src.columns.e_y_px) || [];
  // the estimates up to the pass: after it the vehicle recovers with the target behind it
  const st = (W.snap && W.snap.status) || {}, tPass = st.intercept_time_s ?? Infinity;
  if (bandCache.src === src && bandCache.n === ys.length && bandCache.tPass === tPass) return bandCache.c;
  let t0 = null; const vals = [];
  for (let i = 0; i < ys.length; i++) {
    if (src.t_s[i] > tPass) break;
    if (ys[i] === null || ys[i] === undefined) continue;
    if (t0 === null) t0 = src.t_s[i];
    if (src.t_s[i] >= t0 + TRANSIENT_S) vals.push(ys[i]);
  }
  vals.sort((a, b) => a - b);
  bandCache = { n: ys.length, src, tPass, c: vals.length ? vals[Math.floor(vals.length / 2)] : null };
  return bandCache.c;
}
// The estimates of the last TRACK_S before the time shown (running or replayed alike).
function recentTrack() {
  const src = PV.own, ex = colOf(src, "e_x_px"), ey = colOf(src, "e_y_px"), t = src.t_s, out = [];
  let i = t.length - 1;
  while (i >= 0 && t[i] > PV.tNow + 1e-6) i--;
  for (; i >= 0 && t[i] >= PV.tNow - TRACK_S; i--) if (ex[i] !== null && ey[i] !== null && ex[i] !== undefined) out.push([ex[i], ey[i]]);
  return out.reverse();
}

// An estimate outside the image: an arrow on the edge pointing at it, with its distance.
function drawEdgeArrow(ctx, im, cu, cv, x, y) {
  const dx = x - cu, dy = y - cv, m = 18;
  const k = Math.min(Math.abs((cu - m) / (dx || 1e-9)), Math.abs((cv - m) / (dy || 1e-9)));
  const ex = cu + dx * k, ey = cv + dy * k, ang = Math.atan2(dy, dx);
  ctx.save(); ctx.translate(ex, ey); ctx.rotate(ang);
  ctx.fillStyle = "#19c15b"; ctx.strokeStyle = "#0b5e2c"; ctx.lineWidth = 1.5;
  ctx.beginPath(); ctx.moveTo(14, 0); ctx.lineTo(-8, -10); ctx.lineTo(-8, 10); ctx.closePath(); ctx.fill(); ctx.stroke();
  ctx.restore();
  const off = Math.hypot(dx, dy) - Math.hypot(ex - cu, ey - cv);
  ctx.fillStyle = "#0b5e2c"; ctx.font = "bold 12px sans-serif";
  ctx.fillText(`estimate ${off.toFixed(0)} px outside`, Math.min(Math.max(ex - 60, 4), im.w - 150), Math.min(Math.max(ey + (ey > cv ? -16 : 24), 14), im.h - 6));
  W.edgeArrow = { x: ex, y: ey };
}
