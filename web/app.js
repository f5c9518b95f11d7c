// Peregrine ground station page: telemetry websocket -> status, image plane, plots;
// REST API <- simulator controls and gains. Same origin; the access cookie rides along.
//
// The page is a few classic scripts sharing its globals (index.html loads them in this order):
// web/common.js (lookup, escaping, the REST call), then web/dashboard/: state.js (the counters
// window.peregrine), plots.js, image.js (the image plane), status.js (header, banner, controls
// in force, the live vehicle), telemetry.js (the websocket and the redraw), replay.js,
// controls.js (the simulator's), gains.js, scene.js (the 3D view's frame), studies.js; and
// last this file, which starts the page once every part is loaded.
"use strict";

// the option lists (laws, cameras, speeds) come from GET /api/meta first: the controls can
// then show what is in force
window.peregrineMeta.catch((e) => msg($("sim-msg"), e.message, false)).then(() => {
  loadScenarios().then(loadGains).then(compareFromUrl).catch((e) => msg($("sim-msg"), e.message, false));
  loadStudies().catch((e) => msg($("study-msg"), e.message, false));
  connect();
});
