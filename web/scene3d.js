// Runs in the 3D view's page (viser's client, /viser/) before viser's own scripts: the 3D
// view is drawn only as often as the eye needs, so it leaves the machine to the plots and
// numbers, which get every telemetry message.
//
// Chromium without a GPU (a laptop without one, a headless browser) renders WebGL in software
// (SwiftShader, llvmpipe) and composites in software too: each 3D frame is then read back to
// the CPU (glReadPixels) on its page's thread, which waits there until the GPU process, shared
// by every tab, has drawn it (the dashboard therefore loads this page from another origin, in
// a process of its own: see app.js). With software WebGL the view is drawn at half resolution
// (viser's fixedDpr) without multisampling, at SCENE_IDLE_FPS_SOFTWARE frames per second while
// nobody moves its camera. The scene itself
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
  // viser's notices (e.g. "Software WebGL rendering detected") go small to the top-left corner
  // and fade out after a few seconds; viser's control panel (the View control), which in a
  // view this narrow is a sheet at the bottom, goes small to the top-right corner: neither
  // covers the bottom of the view (the ground, the engagement's start)
  const notices = document.createElement("style");
  notices.textContent = [
    ".mantine-Notifications-root{top:6px!important;bottom:auto!important;left:6px!important;right:auto!important;width:230px!important;transform:scale(.7);transform-origin:top left;animation:peregrine-fade .8s 6s forwards}",
    "@keyframes peregrine-fade{to{opacity:0;visibility:hidden}}",
    '.mantine-Paper-root[style*="position: fixed"][style*="bottom: 0px"]{top:4px!important;bottom:auto!important;right:4px!important;max-height:96px!important;min-height:0!important;opacity:.92}',
    '.mantine-Paper-root[style*="position: fixed"][style*="bottom: 0px"] [style*="width: 20em"]{width:14em!important}',
    // the View control's label in a narrow column, its value ("fit engagement") whole
    '.mantine-Paper-root[style*="position: fixed"][style*="bottom: 0px"] .mantine-Flex-root > :first-child{width:3.2em!important;min-width:0!important;flex:none!important}',
    '.mantine-Paper-root[style*="position: fixed"][style*="bottom: 0px"] .mantine-Select-input{min-width:8.6em}',
  ].join("\n");
  document.head.appendChild(notices);
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
