// The page's shared state: the counters the benchmarks and tests read (window.peregrine) and
// the 2D canvases drawn on the CPU when WebGL is software.
// A part of the dashboard page (web/app.js lists them); the parts share the page's globals.
"use strict";

// counters the benchmark reads (groundstation bench --dashboard): telemetry messages received,
// applied (appended to the plots' series, the readouts' state updated) and painted (animation
// frames that showed new data; updates is the same count)
const W = (window.peregrine = { received: 0, applied: 0, updates: 0, lastT: null, snap: null });

// Without a GPU, Chromium renders "GPU" work in software (SwiftShader) in the GPU process, one
// for all tabs: an accelerated 2D canvas (the image plane, every plot) then sends each stroke
// there and waits for it (in a trace of 5 viewers most of each page's busy time). With a
// software renderer the page's 2D canvases are drawn on the CPU in the page's own process
// instead (willReadFrequently asks for exactly that): with 5 viewers, a page's main thread went
// from 79 % to 62 % busy and painted 2-5 frames/s instead of about 1 (groundstation bench --dashboard).
W.softwareGl = (() => {
  try {
    const gl = document.createElement("canvas").getContext("webgl");
    if (!gl) return true; // no WebGL at all: no GPU either
    const ext = gl.getExtension("WEBGL_debug_renderer_info");
    const name = String(gl.getParameter(ext ? ext.UNMASKED_RENDERER_WEBGL : gl.RENDERER));
    const lose = gl.getExtension("WEBGL_lose_context");
    if (lose) lose.loseContext();
    return /swiftshader|llvmpipe|softpipe|software/i.test(name); // as web/scene3d.js
  } catch (e) { return false; }
})();
if (W.softwareGl) {
  const getContext = HTMLCanvasElement.prototype.getContext;
  HTMLCanvasElement.prototype.getContext = function (type, options) {
    if (type === "2d") options = Object.assign({ willReadFrequently: true }, options || {});
    return getContext.call(this, type, options);
  };
}
