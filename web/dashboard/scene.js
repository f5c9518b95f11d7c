// The 3D view's frame (viser), loaded from its own port and only in a visible tab.
// A part of the dashboard page (web/app.js lists them); the parts share the page's globals.
"use strict";

// The 3D view only in a visible tab: a hidden one drops its viser connection (viser replays
// the whole scene when it reconnects), so background tabs cost the machine almost nothing.
// It is loaded from the server's 3D-view port when there is one (GET /api/scene): another
// origin, so the browser gives it a process of its own and its WebGL never stalls this page's
// thread (see SceneListener in groundstation/app/scene_listener.py). It draws itself only as often as
// the eye needs and moves viser's notices out of the way: web/scene3d.js, run in its page.
let sceneUrl = null;
function syncSceneToVisibility() {
  const frame = $("viser");
  const visible = document.visibilityState === "visible";
  if (sceneUrl === null) return;
  if (visible && frame.dataset.live !== "1") { frame.src = sceneUrl; frame.dataset.live = "1"; }
  if (!visible && frame.dataset.live === "1") { frame.src = "about:blank"; frame.dataset.live = "0"; }
}
document.addEventListener("visibilitychange", syncSceneToVisibility);
api("GET", "/api/scene").then((r) => r.port, () => null).then((port) => {
  sceneUrl = port ? `${location.protocol}//${location.hostname}:${port}/viser/` : "/viser/";
  syncSceneToVisibility();
});
