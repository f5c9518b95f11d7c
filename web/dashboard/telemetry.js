// The telemetry websocket: each message taken in at once, the views redrawn once per frame.
// A part of the dashboard page (web/app.js lists them); the parts share the page's globals.
"use strict";

// Each message is taken in at once (cheap: parse, append to the plots' data); the views are
// redrawn at most once per animation frame, so a slow machine draws less often instead of
// falling behind. window.peregrine counts the messages received, those applied to the plots'
// series and readouts (every one of a running sortie) and the redraws that showed new data.
let pending = null;
let frameRequested = false;

function takeSnapshot(s) {
  W.received += 1; W.snap = s;
  if (s.events && s.events.length !== PV.events.length && !loading) { PV.events = s.events; PV.dirty = true; showGainEdits(); }
  if (s.t !== undefined) {
    W.lastT = s.t;
    // a replayed frame comes with its recorded time: the last decoded for the newest
    // snapshot is shown (an older one decoded late is dropped), none where none was recorded.
    // While a replayed frame decodes the page is not redrawn: the image plane then never
    // shows a newer time over the frame before (the frame follows the cursor as it plays)
    if (s.frame_t_s === null) { img.frame = null; img.seq = ++img.asked; W.frameT = null; W.frameFor = s.t; }
    if (s.frame_jpeg_b64) {
      const im = new Image(), seq = ++img.asked, ft = s.frame_t_s, at = s.t;
      im.frameT = ft === undefined ? null : ft;
      if (ft !== undefined) img.decoding = seq;
      const done = () => {
        if (img.decoding === seq) img.decoding = 0;
        if (!frameRequested) { frameRequested = true; requestAnimationFrame(redraw); }
      };
      im.onload = () => {
        if (seq >= img.seq) { img.seq = seq; img.frame = im; W.frameT = im.frameT; W.frameFor = at; pending = pending || W.snap; }
        done();
      };
      im.onerror = done;
      im.src = "data:image/jpeg;base64," + s.frame_jpeg_b64;
    }
    if (appendLive(s)) W.applied += 1;
    if (PV.tNow !== s.t) { PV.tNow = s.t; PV.dirty = true; }
  }
  pending = s;
  if (!frameRequested) { frameRequested = true; requestAnimationFrame(redraw); }
}

function redraw() {
  frameRequested = false;
  if (img.decoding) return; // drawn once the replayed frame has decoded (takeSnapshot)
  const s = pending; if (!s) return;
  pending = null;
  W.updates += 1; W.shownT = s.t;
  showStatus(s.status);
  drawImagePlane(s);
  refreshPlots(false);
  if (PV.dirty && !plotTimer) plotTimer = setTimeout(() => { plotTimer = null; refreshPlots(false); }, 110);
}
let plotTimer = null;

function connect() {
  const ws = new WebSocket((location.protocol === "https:" ? "wss://" : "ws://") + location.host + "/ws/telemetry");
  // a hidden tab asks for no camera frames: it cannot show them
  const wantFrames = () => { if (ws.readyState === 1) ws.send(JSON.stringify({ frames: document.visibilityState === "visible" })); };
  ws.onopen = () => { setBadge("st-link", "telemetry: live", "ok"); wantFrames(); };
  document.addEventListener("visibilitychange", wantFrames);
  ws.onmessage = (ev) => takeSnapshot(JSON.parse(ev.data));
  ws.onclose = () => { setBadge("st-link", "telemetry: reconnecting", "bad"); setTimeout(connect, 1000); };
}
