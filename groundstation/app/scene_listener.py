"""The 3D view's own listener: viser's client and its websocket served on a port of their own
(same address, same token), so that the browser gives the 3D view a process of its own."""

from __future__ import annotations

import threading
import time
from typing import Any

import uvicorn

SCENE_PATHS = ("/viser/", "/viser", "/static/scene3d.js")


class SceneListener:
    """The 3D view (viser's client and its websocket) on a port of its own, same address, same
    token (the access cookie is the host's, whatever the port), nothing else served there.

    Another port is another origin; with ``Origin-Agent-Cluster: ?1`` Chromium gives the 3D
    view's frame a process of its own. Its WebGL then never stalls the dashboard's thread:
    a browser that renders WebGL in software (no GPU) reads every 3D frame back on the thread
    of the page that drew it, and in the page's own process that thread is the one drawing the
    plots and numbers (5 headless viewers on 2 cores: 0.4 frames/s painted with the 3D view in
    the page's process, 1.0-1.6 with it in its own)."""

    def __init__(self, app: Any, host: str, port: int = 0) -> None:
        async def scene_only(scope, receive, send):
            if scope.get("path") not in SCENE_PATHS:
                if scope["type"] == "websocket":
                    await send({"type": "websocket.close", "code": 1008})
                    return
                await send({"type": "http.response.start", "status": 404, "headers": []})
                await send({"type": "http.response.body", "body": b""})
                return

            async def send_isolated(message):
                if message["type"] == "http.response.start":
                    headers = [*message.get("headers", []), (b"origin-agent-cluster", b"?1")]
                    message = {**message, "headers": headers}
                await send(message)

            await app(scope, receive, send_isolated)

        self.server = uvicorn.Server(
            uvicorn.Config(
                scene_only,
                host=host,
                port=port,
                log_level="warning",
                ws="websockets-sansio",
                lifespan="off",  # the dashboard's listener runs the app's lifespan
            )
        )
        self._thread = threading.Thread(target=self.server.run, name="scene-http", daemon=True)

    @property
    def port(self) -> int | None:
        """The port it listens on, None until it does (or if it could not)."""
        if not self.server.started:
            return None
        for srv in getattr(self.server, "servers", []):
            for sock in srv.sockets:
                return sock.getsockname()[1]
        return None

    def start(self, timeout_s: float = 10.0) -> None:
        """Listen; if it cannot (the port taken), the page serves the 3D view itself."""
        self._thread.start()
        deadline = time.monotonic() + timeout_s
        while not self.server.started and self._thread.is_alive():
            if time.monotonic() > deadline:
                break
            time.sleep(0.02)

    def stop(self) -> None:
        self.server.should_exit = True
        if self._thread.is_alive():
            self._thread.join(timeout=10.0)
