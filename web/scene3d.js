// Runs in the 3D view's page (viser's client, /viser/) before viser's own scripts: the 3D
// view is drawn only as often as the eye needs, so it leaves the page's thread to the plots
// and numbers, which get every telemetry message.
//
// The 3D view shares the dashboard page's thread (same origin). Chromium without a GPU (a
// laptop without one, a headless browser) renders its WebGL in software (SwiftShader,
// llvmpipe) and composites in software too: each 3D frame is then read back to the CPU
// (glReadPixels) on the page's thread, which waits there until the shared GPU process has
// drawn it; with 5 viewers that wait was most of every page's time. With software WebGL the
// view is therefore drawn at half resolution (viser's fixedDpr) without multisampling, at
// SCENE_IDLE_FPS_SOFTWARE frames per second while nobody moves its camera. The scene itself
// changes 5 times a second (SCENE_EVERY on the server), so a GPU draws it at that rate. While
// the operator moves the camera (pointer, wheel or key in the view, for 1.5 s after the last
// such event) it is drawn at the display's rate.
"use strict";
(() => {
  const SCENE_IDLE_FPS = 5;
  const SCENE_IDLE_FPS_SOFTWARE = 2.5;
  const SOFTWARE_DPR = 0.5;
  const rendererName = () => {
    try {
      const gl = document.createElement("canvas").getContext("webgl");
      if (!gl) return "";
      const ext = gl.getExtension("WEBGL_debug_renderer_info");
      const name = String(gl.getParameter(ext ? ext.UNMASKED_RENDERER_WEBGL : gl.RENDERER));
      const lose = gl.getExtension("WEBGL_lose_context");
      if (lose) lose.loseContext();
      return name;
    } catch (e) { return ""; }
  };
  // the renderers viser itself calls software ("Software WebGL rendering detected")
  const software = /swiftshader|llvmpipe|softpipe|software/i.test(rendererName());
  const q = new URLSearchParams(location.search);
  if (software && !q.has("fixedDpr")) {
    q.set("fixedDpr", String(SOFTWARE_DPR));
    history.replaceState(history.state, "", location.pathname + "?" + q.toString() + location.hash);
  }
  if (software) {
    const getContext = HTMLCanvasElement.prototype.getContext;
    HTMLCanvasElement.prototype.getContext = function (type, options) {
      if (type === "webgl2" || type === "webgl") options = Object.assign({}, options || {}, { antialias: false });
      return getContext.call(this, type, options);
    };
  }
  const idleFps = software ? SCENE_IDLE_FPS_SOFTWARE : SCENE_IDLE_FPS;
  window.peregrineScene = { software, idleFps };
  const raf = window.requestAnimationFrame.bind(window);
  let activeUntil = 0, last = 0;
  const poke = () => { activeUntil = performance.now() + 1500; };
  for (const ev of ["pointerdown", "pointermove", "wheel", "keydown", "touchstart"]) document.addEventListener(ev, poke, { capture: true, passive: true });
  window.requestAnimationFrame = (cb) => {
    const now = performance.now();
    if (now < activeUntil) return raf(cb);
    const wait = Math.max(0, last + 1000 / idleFps - now);
    return window.setTimeout(() => raf((ts) => { last = performance.now(); cb(ts); }), wait);
  };
})();
