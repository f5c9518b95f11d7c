"""``groundstation serve``: FastAPI serves the dashboard page, the REST API (OpenAPI at /docs),
the telemetry websocket and viser's client, and proxies viser's websocket, so the operator
reaches everything through one address and one token check. viser listens on loopback only.

The REST API is one router per concern: meta and scenarios (routes_scenarios.py), gains
(routes_gains.py), the sortie and the live vehicle (routes_sortie.py), recorded sorties and
replay (routes_logs.py); their request and response models are in api_models.py."""

from __future__ import annotations

import asyncio
import contextlib
import importlib.util
import io
import json
import socket
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import uvicorn
import viser
import websockets.asyncio.client
from fastapi import FastAPI, WebSocket
from fastapi.encoders import jsonable_encoder
from fastapi.exceptions import RequestValidationError
from fastapi.responses import HTMLResponse, JSONResponse, Response
from fastapi.staticfiles import StaticFiles

from onboard.link.address import bind_tcp_listener

from ..recording.reader import LogIndex
from ..scenario import ScenarioError
from . import routes_gains, routes_logs, routes_scenarios, routes_sortie, routes_studies
from .auth import TokenAuthMiddleware, is_loopback, new_token
from .gainsets import GainSetStore, default_data_dir
from .protocol import Session
from .scene import SceneView
from .scene_listener import SceneListener
from .session import SimSession
from .telemetry_hub import TelemetryHub

VISER_INDEX = Path(viser.__file__).parent / "client" / "build" / "index.html"


def web_dir() -> Path:
    """The dashboard's static files: groundstation/web of an installed package (a folder of
    pages, not a Python package), or web/ of a source checkout."""
    try:
        spec = importlib.util.find_spec("groundstation.web")
    except ModuleNotFoundError:
        spec = None
    for location in (spec.submodule_search_locations or []) if spec else []:
        if (Path(location) / "index.html").is_file():
            return Path(location)
    return Path(__file__).resolve().parents[2] / "web"


def create_app(
    session: Session,
    hub: TelemetryHub,
    token: str | None,
    viser_port: int,
    gainsets: GainSetStore,
    logs: LogIndex | None = None,
    studies_url: Callable[[], str] | None = None,
    scene_port: Callable[[], int | None] = lambda: None,
) -> FastAPI:
    """``studies_url``: the gain studies' storage URL, asked at the first request about them;
    ``scene_port``: the port of the 3D view's own listener (:class:`SceneListener`) once it
    listens, None to serve the 3D view from this origin."""
    logs = logs or LogIndex(Path("logs"))

    @contextlib.asynccontextmanager
    async def lifespan(_app: FastAPI):
        hub.loop = asyncio.get_running_loop()
        yield

    app = FastAPI(
        title="Peregrine ground station",
        version="0.1.0",
        lifespan=lifespan,
        description="Simulator control, gains and telemetry for the Peregrine interceptor.",
    )

    @app.exception_handler(RequestValidationError)
    async def readable_422(_request, exc: RequestValidationError) -> JSONResponse:
        """A refused request says why in one line the page can show (the field and pydantic's
        message, which lists a Literal's choices), the structured errors beside it."""
        why = "; ".join(
            ".".join(str(p) for p in e["loc"] if p != "body") + ": " + e["msg"]
            for e in exc.errors()
        )
        return JSONResponse(
            status_code=422, content={"detail": why, "errors": jsonable_encoder(exc.errors())}
        )

    # ------------------------------------------------------------------ pages
    @app.get("/", include_in_schema=False)
    async def index() -> HTMLResponse:
        return HTMLResponse((web_dir() / "index.html").read_text(encoding="utf-8"))

    app.mount("/static", StaticFiles(directory=web_dir()), name="static")

    @app.get("/favicon.ico", include_in_schema=False)
    async def favicon() -> Response:
        return Response(status_code=204)

    @app.get("/overlay", include_in_schema=False)
    async def overlay_page() -> HTMLResponse:
        return HTMLResponse((web_dir() / "overlay.html").read_text(encoding="utf-8"))

    @app.get("/sorties", include_in_schema=False)
    async def sorties_page() -> HTMLResponse:
        return HTMLResponse((web_dir() / "sorties.html").read_text(encoding="utf-8"))

    # viser's client, with web/scene3d.js run first: it draws the 3D view only as often as
    # the eye needs (and cheaply with software WebGL), see that file
    viser_html = VISER_INDEX.read_text(encoding="utf-8").replace(
        "<head>", '<head><script src="/static/scene3d.js"></script>', 1
    )

    @app.get("/viser/", include_in_schema=False)
    async def viser_page() -> HTMLResponse:
        return HTMLResponse(viser_html)

    @app.get("/api/scene", include_in_schema=False)
    async def scene_location() -> dict[str, int | None]:
        """Where the page loads its 3D view from: this host at ``port`` (None: this origin)."""
        return {"port": scene_port()}

    @app.websocket("/viser")
    async def viser_proxy(ws: WebSocket) -> None:
        protos = list(ws.scope.get("subprotocols", []))
        try:
            upstream = await websockets.asyncio.client.connect(
                f"ws://127.0.0.1:{viser_port}",
                subprotocols=protos or None,
                max_size=50 * 1024 * 1024,
                compression=None,
                open_timeout=5,
            )
        except (OSError, websockets.exceptions.WebSocketException):
            await ws.close(code=1011)
            return
        await ws.accept(subprotocol=upstream.subprotocol)

        async def down() -> None:
            async for msg in upstream:
                if isinstance(msg, bytes):
                    await ws.send_bytes(msg)
                else:
                    await ws.send_text(msg)

        async def up() -> None:
            while True:
                m = await ws.receive()
                if m["type"] == "websocket.disconnect":
                    return
                if m.get("bytes") is not None:
                    await upstream.send(m["bytes"])
                elif m.get("text") is not None:
                    await upstream.send(m["text"])

        tasks = [asyncio.create_task(down()), asyncio.create_task(up())]
        try:
            await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
        finally:
            for t in tasks:
                t.cancel()
            await upstream.close()
            with contextlib.suppress(Exception):
                await ws.close()

    # ------------------------------------------------------------------ telemetry
    @app.websocket("/ws/telemetry")
    async def telemetry(ws: WebSocket) -> None:
        await ws.accept()
        session.request_frame()  # a page that (re)loads shows the camera frame at once
        q: asyncio.Queue = asyncio.Queue(maxsize=4)
        hub.queues[q] = True
        key = id(q)
        hub.sent[key] = 0

        async def listen() -> None:
            while True:
                try:
                    msg = json.loads(await ws.receive_text())
                except (ValueError, TypeError):
                    continue  # garbage from a client changes nothing
                if isinstance(msg, dict) and isinstance(msg.get("frames"), bool):
                    hub.queues[q] = msg["frames"]

        async def pump() -> None:
            if hub.last is not None:
                await ws.send_text(hub.last)
            while True:
                await ws.send_text((await q.get())[1])
                hub.sent[key] += 1

        tasks = [asyncio.create_task(listen()), asyncio.create_task(pump())]
        try:
            await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
        finally:
            for t in tasks:
                t.cancel()
            hub.queues.pop(q, None)
            hub.sent.pop(key, None)

    # ------------------------------------------------------------------ API, by concern
    app.include_router(routes_scenarios.router())
    app.include_router(routes_gains.router(session, gainsets))
    app.include_router(routes_sortie.router(session))
    app.include_router(routes_logs.router(session, logs))
    if studies_url is not None:
        app.include_router(routes_studies.router(session, studies_url, session.log_dir))

    _declare_errors(app)
    return TokenAuthMiddleware(app, token)  # type: ignore[return-value]


def _declare_errors(app: FastAPI) -> None:
    """A refused scenario answers 422 with every problem located
    (:meth:`ScenarioError.to_json_dict`: ``detail``, ``source``, ``problems``), and the OpenAPI
    document declares the app's 422 shape as sent: ``detail`` is one sentence (or FastAPI's
    list of field errors)."""

    @app.exception_handler(ScenarioError)
    async def scenario_error(_request: Any, exc: ScenarioError) -> JSONResponse:
        return JSONResponse(exc.to_json_dict(), status_code=422)

    make_document = app.openapi

    def document() -> dict[str, Any]:
        if app.openapi_schema is None:
            doc = make_document()
            error = doc.get("components", {}).get("schemas", {}).get("HTTPValidationError")
            if error is not None:
                props = error["properties"]
                props["detail"] = {
                    "anyOf": [props["detail"], {"type": "string"}],
                    "title": "Detail",
                }
                props["problems"] = {"type": "array", "items": {"type": "object"}}
        return app.openapi_schema

    app.openapi = document  # type: ignore[method-assign]


def studies_storage_url(data_dir: Path) -> str:
    """Where ``groundstation tune`` keeps its studies by default (the same data folder)."""
    from ..campaigns.tune import default_storage_url  # slow to import: not at the start

    return default_storage_url(data_dir)


def free_loopback_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class GroundStation:
    """Everything ``serve`` starts, with a clean stop (frees both ports)."""

    def __init__(
        self,
        host: str = "127.0.0.1",
        port: int = 8000,
        no_auth: bool = False,
        data_dir: Path | None = None,
        log_dir: Path | None = Path("logs"),
        mavlink_url: str | None = None,
        signing_key: bytes | None = None,
        foxglove=None,
        video: tuple[str, int] | None = None,
        scene_port: int | None = 0,
    ) -> None:
        """``foxglove``: a :class:`~onboard.channels.live.FoxgloveLive` to publish
        every sortie's channels on (None: none); ``video``: (host, port) to receive the
        vehicle's RTP video on (live mode); ``scene_port``: the 3D view's own port
        (:class:`SceneListener`; 0: any free one, None: served from the dashboard's origin)."""
        if no_auth and not is_loopback(host):
            raise ValueError(f"--no-auth is refused on a non-loopback address ({host})")
        if video is not None and mavlink_url is None:
            raise ValueError("--video is for live mode (with --mavlink)")
        self.host = host
        self.token = None if no_auth else new_token()
        with contextlib.redirect_stdout(io.StringIO()):  # viser's banner: one URL is ours
            self.viser = viser.ViserServer(
                host="127.0.0.1", port=free_loopback_port(), verbose=False
            )
        self.viser_port = self.viser.get_port()
        self.hub = TelemetryHub()
        self.scene = SceneView(self.viser)
        self.log_dir = log_dir
        self.live = mavlink_url is not None
        if mavlink_url is not None:
            from .live import LiveSession

            self.session = LiveSession(
                mavlink_url,
                signing_key,
                on_snapshot=self.hub.publish_from_thread,
                scene=self.scene,
                log_dir=log_dir,
            )
        else:
            self.session = SimSession(
                on_snapshot=self.hub.publish_from_thread, scene=self.scene, log_dir=log_dir
            )
        self.session.foxglove = foxglove
        if video is not None:
            from .video import VideoReceiver

            self.session.video = VideoReceiver(*video)
            self.session.video.start()
        self.data_dir = data_dir or default_data_dir()
        self.gainsets = GainSetStore(self.data_dir / "gainsets")
        self.app = create_app(
            self.session,
            self.hub,
            self.token,
            self.viser_port,
            self.gainsets,
            LogIndex(log_dir or Path("logs")),
            lambda: studies_storage_url(self.data_dir),
            scene_port=lambda: None if self.scene_http is None else self.scene_http.port,
        )
        self.scene_http = None if scene_port is None else SceneListener(self.app, host, scene_port)
        self.server = uvicorn.Server(
            uvicorn.Config(
                self.app,
                host=host,
                port=port,
                log_level="warning",
                ws="websockets-sansio",
                lifespan="on",
            )
        )
        self._thread: threading.Thread | None = None
        # port 0: a free port taken now and handed to the server, so the URL printed before
        # it serves (``groundstation serve --port 0``) carries the real port
        self._listening = bind_tcp_listener(host, 0) if port == 0 else None

    @property
    def _sockets(self) -> list[socket.socket] | None:
        return None if self._listening is None else [self._listening]

    @property
    def port(self) -> int:
        if self._listening is not None:
            return self._listening.getsockname()[1]
        for srv in getattr(self.server, "servers", []):
            for sock in srv.sockets:
                return sock.getsockname()[1]
        return self.server.config.port

    def url(self) -> str:
        shown = "127.0.0.1" if self.host in ("0.0.0.0", "::") else self.host
        base = f"http://{shown}:{self.port}/"
        return base if self.token is None else f"{base}?token={self.token}"

    def start_in_thread(self, timeout_s: float = 10.0) -> None:
        if self.scene_http is not None:
            self.scene_http.start()
        self._thread = threading.Thread(
            target=self.server.run, kwargs={"sockets": self._sockets}, daemon=True
        )
        self._thread.start()
        deadline = time.monotonic() + timeout_s
        while not self.server.started:
            if time.monotonic() > deadline or not self._thread.is_alive():
                raise RuntimeError("the ground station did not start")
            time.sleep(0.02)

    def run_forever(self) -> None:
        if self.scene_http is not None:
            self.scene_http.start()
        try:
            self.server.run(sockets=self._sockets)
        finally:
            self.close()

    def stop(self) -> None:
        self.server.should_exit = True
        if self._thread is not None:
            self._thread.join(timeout=10.0)
        self.close()

    def close(self) -> None:
        if self.scene_http is not None:
            self.scene_http.stop()
        self.session.close()
        if self.session.foxglove is not None:
            self.session.foxglove.stop()
        if getattr(self.session, "video", None) is not None:
            self.session.video.stop()
        with contextlib.redirect_stdout(io.StringIO()):
            self.viser.stop()
        if self._listening is not None:
            self._listening.close()
