// A 3D view of trajectories relative to the target (the target fixed at the origin; east,
// north, up in metres), drawn on a 2D canvas: drag to turn it, wheel to zoom, and three
// presets (3D, plan from above, side from the east). The tracks are drawn once per view pose
// into an offscreen copy; a cursor frame copies it and adds one dot per sortie.
// Orthographic: the eye looks at the origin from azimuth az (degrees from east towards north)
// and elevation el (degrees above the horizon).
"use strict";
window.RelView = class RelView {
  static PRESETS = { "3d": [-115, 28], plan: [-90, 90], side: [0, 0] };

  constructor(canvas, onChange) {
    this.canvas = canvas;
    this.onChange = onChange || (() => {});
    this.tracks = []; // [{color, points: [[e, n, u], ...]}]
    this.extent = 1;
    [this.az, this.el] = RelView.PRESETS["3d"];
    this.zoom = 1;
    this.base = null;
    let drag = null;
    canvas.addEventListener("pointerdown", (ev) => { drag = [ev.clientX, ev.clientY, this.az, this.el]; canvas.setPointerCapture(ev.pointerId); });
    canvas.addEventListener("pointermove", (ev) => {
      if (!drag) return;
      const [x0, y0, az0, el0] = drag;
      this.pose(az0 - (ev.clientX - x0) * 0.5, Math.min(90, Math.max(-90, el0 + (ev.clientY - y0) * 0.5)));
    });
    canvas.addEventListener("pointerup", () => { drag = null; });
    canvas.addEventListener("wheel", (ev) => {
      ev.preventDefault();
      this.zoom = Math.min(20, Math.max(0.2, this.zoom * Math.exp(-ev.deltaY * 0.001)));
      this.base = null; this.onChange();
    }, { passive: false });
  }

  setView(name) { const [az, el] = RelView.PRESETS[name]; this.zoom = 1; this.pose(az, el); }

  pose(az, el) { this.az = az; this.el = el; this.base = null; this.onChange(); }

  setTracks(tracks) {
    this.tracks = tracks;
    let m = 1;
    for (const t of tracks) for (const r of t.points) m = Math.max(m, Math.abs(r[0]), Math.abs(r[1]), Math.abs(r[2]));
    this.extent = m; // the farthest coordinate (m): the view's scale
    this.base = null;
  }

  // the screen position (canvas px) of a point relative to the target
  project(r) {
    const a = (this.az * Math.PI) / 180, e = (this.el * Math.PI) / 180;
    const sa = Math.sin(a), ca = Math.cos(a), se = Math.sin(e), ce = Math.cos(e);
    const x = -sa * r[0] + ca * r[1]; // along the view's right
    const y = -se * ca * r[0] - se * sa * r[1] + ce * r[2]; // along the view's up
    const { width: W, height: H } = this.canvas;
    const sc = ((Math.min(W, H) / 2 - 18) / this.extent) * this.zoom;
    return [W / 2 + x * sc, H / 2 - y * sc];
  }

  drawBase(ctx) {
    const { width: W, height: H } = this.canvas, m = this.extent, P = (r) => this.project(r);
    ctx.clearRect(0, 0, W, H);
    // the target's horizontal plane: a grid of 8 x 8 cells over the extent
    ctx.strokeStyle = "#e3e8ec"; ctx.lineWidth = 1; ctx.beginPath();
    for (let k = -4; k <= 4; k++) {
      const c = (k / 4) * m;
      for (const [p, q] of [[[c, -m, 0], [c, m, 0]], [[-m, c, 0], [m, c, 0]]]) { const a = P(p), b = P(q); ctx.moveTo(a[0], a[1]); ctx.lineTo(b[0], b[1]); }
    }
    ctx.stroke();
    ctx.font = "12px sans-serif";
    for (const [axis, name, color] of [[[1, 0, 0], "east", "#b03a2e"], [[0, 1, 0], "north", "#1e8449"], [[0, 0, 1], "up", "#2e5aa8"]]) {
      const o = P([0, 0, 0]), t = P(axis.map((c) => c * m * 0.5));
      ctx.strokeStyle = color; ctx.lineWidth = 1.5; ctx.beginPath(); ctx.moveTo(o[0], o[1]); ctx.lineTo(t[0], t[1]); ctx.stroke();
      ctx.fillStyle = color; ctx.fillText(name, t[0] + 3, t[1] - 3);
    }
    for (const t of this.tracks) {
      ctx.strokeStyle = t.color; ctx.lineWidth = 1.3; ctx.beginPath();
      t.points.forEach((r, j) => { const [x, y] = P(r); if (j) ctx.lineTo(x, y); else ctx.moveTo(x, y); });
      ctx.stroke();
    }
    ctx.fillStyle = "#d7263d"; const o = P([0, 0, 0]);
    ctx.beginPath(); ctx.arc(o[0], o[1], 5, 0, 2 * Math.PI); ctx.fill(); // the target
    ctx.fillStyle = "#47525d";
    ctx.fillText(`relative to the target · grid ${window.fmtNum(m / 4)} m cells · drag: turn · wheel: zoom`, 8, 14);
  }

  // the tracks, and one dot per sortie at ``dots`` ([[color, [e, n, u]] or null, ...])
  draw(dots) {
    const cv = this.canvas, ctx = cv.getContext("2d");
    if (!this.base) {
      this.base = document.createElement("canvas");
      this.base.width = cv.width; this.base.height = cv.height;
      this.drawBase(this.base.getContext("2d"));
    }
    ctx.clearRect(0, 0, cv.width, cv.height);
    ctx.drawImage(this.base, 0, 0);
    for (const d of dots) {
      if (!d) continue;
      const [x, y] = this.project(d[1]);
      ctx.fillStyle = d[0]; ctx.beginPath(); ctx.arc(x, y, 4, 0, 2 * Math.PI); ctx.fill();
    }
  }
};
