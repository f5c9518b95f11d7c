"""``groundstation serve``: FastAPI serves the dashboard page, the REST API (OpenAPI at /docs),
the telemetry websocket and viser's client, and proxies viser's websocket, so the operator
reaches everything through one address and one token check. viser listens on loopback only."""

from __future__ import annotations

import asyncio
import contextlib
import importlib.util
import io
import json
import math
import socket
import threading
import time
from pathlib import Path
from typing import Annotated, Any

import uvicorn
import viser
import websockets.asyncio.client
from fastapi import Body, FastAPI, HTTPException, WebSocket
from fastapi.responses import FileResponse, HTMLResponse, Response
from fastapi.staticfiles import StaticFiles
from pydantic import BaseModel, Field

from onboard.control.guidance import GUIDANCE_LAWS
from onboard.gains import GAIN_SPECS, GainError

from ..recording.reader import LogError, LogIndex, scenario_attachment
from ..scenario import ScenarioError, load_scenario, parse_scenario, shipped_scenarios, with_changes
from ..sim.camera import CAMERA_MODES
from .auth import TokenAuthMiddleware, is_loopback, new_token
from .gainsets import GainSetError, GainSetStore, default_data_dir
from .replay import ReplayPlayer
from .scene import SceneView
from .session import SPEEDS, SessionError, SimSession, SortieConfig, with_wind

# the gains panel's groups (in this order), like a parameter editor's
GAIN_GROUPS = {
    "k_a": "guidance",
    "K_y": "guidance",
    "K_z": "guidance",
    "v_min": "guidance",
    "k_v": "guidance",
    "k_ibvs": "guidance",
    "k_p": "FOV hold",
    "k_d": "FOV hold",
    "k_R": "attitude",
    "v_max": "limits",
    "a_max": "limits",
    "omega_max": "limits",
    "k_brake": "limits",
}
_GROUP_ORDER = ["guidance", "FOV hold", "attitude", "limits", "other"]
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


class TelemetryHub:
    """Fans telemetry out to websocket subscribers; a slow one loses old frames, not new.

    A subscriber may send ``{"frames": false}`` (a hidden browser tab does) to stop receiving
    camera frames, the bulk of the traffic, and ``{"frames": true}`` to resume."""

    def __init__(self) -> None:
        self.loop: asyncio.AbstractEventLoop | None = None
        self.queues: dict[asyncio.Queue, bool] = {}  # queue -> wants camera frames
        self.last: str | None = None
        self.sent: dict[int, int] = {}  # messages sent, per connected subscriber

    def publish_from_thread(self, snapshot: dict[str, Any]) -> None:
        full = json.dumps(snapshot, separators=(",", ":"))
        lean = full
        if "frame_jpeg_b64" in snapshot:
            lean = json.dumps(
                {k: v for k, v in snapshot.items() if k != "frame_jpeg_b64"}, separators=(",", ":")
            )
        self.last = lean
        if self.loop is not None and self.queues:
            self.loop.call_soon_threadsafe(self._broadcast, full, lean)

    def _broadcast(self, full: str, lean: str) -> None:
        for q, frames in list(self.queues.items()):
            if q.full():
                with contextlib.suppress(asyncio.QueueEmpty):
                    q.get_nowait()
            q.put_nowait(full if frames else lean)


class ReflyRequest(BaseModel):
    law: str = "png"
    seed: int | None = None
    speed: str = "1"
    gains: dict[str, float] | None = None


class StartRequest(BaseModel):
    scenario: str | None = Field(None, description="name of a shipped scenario")
    toml: str | None = Field(None, description="scenario file text (instead of a name)")
    law: str = "png"
    seed: int = 0
    camera: str = "projected"
    speed: str = "1"
    wind_mean_m_s: list[float] | None = Field(None, min_length=3, max_length=3)
    gust_m_s: float | None = Field(None, ge=0.0)


def _scenario_from(req: StartRequest):
    if (req.scenario is None) == (req.toml is None):
        raise HTTPException(422, "give exactly one of 'scenario' (a name) or 'toml' (file text)")
    try:
        if req.toml is not None:
            scenario = parse_scenario(req.toml, source="uploaded scenario")
        else:
            names = {p.stem for p in shipped_scenarios()}
            if req.scenario not in names:
                raise HTTPException(422, f"unknown scenario {req.scenario!r}")
            scenario = load_scenario(req.scenario)
        if req.wind_mean_m_s is not None or req.gust_m_s is not None:
            scenario = with_wind(
                scenario,
                tuple(req.wind_mean_m_s) if req.wind_mean_m_s else scenario.wind.mean_m_s,
                scenario.wind.gust_m_s if req.gust_m_s is None else req.gust_m_s,
            )
    except ScenarioError as exc:
        raise HTTPException(422, str(exc)) from None
    return scenario


def create_app(
    session: SimSession,
    hub: TelemetryHub,
    token: str | None,
    viser_port: int,
    gainsets: GainSetStore,
    logs: LogIndex | None = None,
) -> FastAPI:
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

    # ------------------------------------------------------------------ pages
    @app.get("/", include_in_schema=False)
    async def index() -> HTMLResponse:
        return HTMLResponse((web_dir() / "index.html").read_text(encoding="utf-8"))

    app.mount("/static", StaticFiles(directory=web_dir()), name="static")

    @app.get("/favicon.ico", include_in_schema=False)
    async def favicon() -> Response:
        return Response(status_code=204)

    @app.get("/sorties", include_in_schema=False)
    async def sorties_page() -> HTMLResponse:
        return HTMLResponse((web_dir() / "sorties.html").read_text(encoding="utf-8"))

    @app.get("/viser/", include_in_schema=False)
    async def viser_page() -> FileResponse:
        return FileResponse(VISER_INDEX, media_type="text/html")

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
        request_frame = getattr(session, "request_frame", None)
        if request_frame is not None:
            request_frame()  # a page that (re)loads shows the camera frame at once
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
                await ws.send_text(await q.get())
                hub.sent[key] += 1

        tasks = [asyncio.create_task(listen()), asyncio.create_task(pump())]
        try:
            await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
        finally:
            for t in tasks:
                t.cancel()
            hub.queues.pop(q, None)
            hub.sent.pop(key, None)

    # ------------------------------------------------------------------ API
    @app.get("/api/scenarios", tags=["scenarios"])
    async def list_scenarios() -> list[dict[str, str]]:
        out = []
        for p in shipped_scenarios():
            s = load_scenario(p)
            out.append({"name": s.name, "motion": s.target.motion, "description": s.description})
        return out

    @app.get("/api/scenarios/{name}", tags=["scenarios"])
    async def get_scenario(name: str) -> dict[str, str]:
        names = {p.stem: p for p in shipped_scenarios()}
        if name not in names:
            raise HTTPException(404, f"unknown scenario {name!r}")
        return {"name": name, "toml": names[name].read_text(encoding="utf-8")}

    @app.post("/api/scenarios/validate", tags=["scenarios"])
    async def validate_scenario(toml: Annotated[str, Body(embed=True)]) -> dict[str, Any]:
        try:
            s = parse_scenario(toml, source="uploaded scenario")
        except ScenarioError as exc:
            raise HTTPException(422, str(exc)) from None
        return {"ok": True, "name": s.name, "motion": s.target.motion}

    @app.get("/api/gains", tags=["gains"])
    async def get_gains() -> dict[str, Any]:
        st = session.status()
        return {
            "values": session.gains.to_dict(),
            "specs": [
                {
                    "name": s.name,
                    "default": s.default,
                    "unit": s.unit,
                    "min": s.minimum,
                    "max": s.maximum,
                    "meaning": s.meaning,
                    "group": GAIN_GROUPS.get(s.name, "other"),
                }
                for s in sorted(
                    GAIN_SPECS, key=lambda s: _GROUP_ORDER.index(GAIN_GROUPS.get(s.name, "other"))
                )
            ],
            "applied_time_s": st["gains_applied_time_s"],
            "pending": st["gains_pending"],
        }

    @app.put("/api/gains", tags=["gains"])
    async def put_gains(changes: Annotated[dict[str, Any], Body()]) -> dict[str, Any]:
        try:
            new = session.gains.replace(**changes)
        except (GainError, TypeError) as exc:
            raise HTTPException(422, str(exc)) from None
        try:
            await asyncio.to_thread(session.set_gains, new)
        except SessionError as exc:
            raise HTTPException(409, str(exc)) from None
        return await get_gains()

    @app.post("/api/gains/reset", tags=["gains"])
    async def reset_gains() -> dict[str, Any]:
        try:
            await asyncio.to_thread(session.set_gains, session.default_gains())
        except SessionError as exc:
            raise HTTPException(409, str(exc)) from None
        return await get_gains()

    @app.get("/api/gainsets", tags=["gains"])
    async def list_gainsets() -> list[str]:
        return gainsets.names()

    @app.put("/api/gainsets/{name}", tags=["gains"])
    async def save_gainset(name: str) -> dict[str, Any]:
        try:
            gainsets.save(name, session.gains)
        except GainSetError as exc:
            raise HTTPException(422, str(exc)) from None
        return {"saved": name, "names": gainsets.names()}

    @app.get("/api/gainsets/{name}/file", tags=["gains"])
    async def download_gainset(name: str) -> Response:
        try:
            text = gainsets.text(name)
        except GainSetError as exc:
            raise HTTPException(404, str(exc)) from None
        return Response(
            text,
            media_type="application/toml",
            headers={"Content-Disposition": f'attachment; filename="{name}.toml"'},
        )

    @app.post("/api/gainsets/upload", tags=["gains"])
    async def upload_gainset(
        name: Annotated[str, Body()], toml: Annotated[str, Body()]
    ) -> dict[str, Any]:
        """Save an uploaded gain set file (``name = value`` lines) under ``name``."""
        try:
            gainsets.save_text(name, toml)
        except (GainSetError, GainError) as exc:
            raise HTTPException(422, str(exc)) from None
        return {"saved": name, "names": gainsets.names()}

    @app.post("/api/gainsets/{name}/load", tags=["gains"])
    async def load_gainset(name: str) -> dict[str, Any]:
        try:
            gains = gainsets.load(name)
        except (GainSetError, GainError) as exc:
            raise HTTPException(422, str(exc)) from None
        try:
            if isinstance(session, SimSession):
                await asyncio.to_thread(session.set_gains, gains, f"gain set {name}")
            else:
                await asyncio.to_thread(session.set_gains, gains)
        except SessionError as exc:
            raise HTTPException(409, str(exc)) from None
        return await get_gains()

    # ------------------------------------------------------------------ recorded sorties
    def _log_path(name: str) -> Path:
        try:
            path = logs.resolve(name)
        except LogError as exc:
            raise HTTPException(400, str(exc)) from None
        if not path.is_file():
            raise HTTPException(404, f"no recorded sortie named {name!r}")
        return path

    def _player(name: str) -> ReplayPlayer:
        try:
            return ReplayPlayer(_log_path(name))
        except (LogError, ValueError) as exc:
            raise HTTPException(422, str(exc)) from None

    @app.get("/api/logs", tags=["logs"])
    async def list_logs() -> list[dict[str, Any]]:
        return await asyncio.to_thread(logs.list)

    @app.get("/api/logs/{name}", tags=["logs"])
    async def log_info(name: str) -> dict[str, Any]:
        try:
            return logs.info(_log_path(name).name).to_json_dict()
        except LogError as exc:
            raise HTTPException(422, str(exc)) from None

    @app.get("/api/logs/{name}/series", tags=["logs"])
    async def log_series(name: str) -> dict[str, Any]:
        return (await asyncio.to_thread(_player, name)).series()

    @app.get("/api/logs/{name}/file", tags=["logs"])
    async def download_log(name: str) -> FileResponse:
        path = _log_path(name)
        return FileResponse(path, media_type="application/octet-stream", filename=path.name)

    @app.delete("/api/logs/{name}", tags=["logs"])
    async def delete_log(name: str, confirm: str = "") -> dict[str, Any]:
        path = _log_path(name)
        if confirm != name:
            raise HTTPException(400, "to delete, repeat the file name in ?confirm=")
        rec = session.recording
        if rec is not None and rec["file"] == name and not rec["closed"]:
            raise HTTPException(409, "this sortie is still being recorded")
        path.unlink()
        return {"deleted": name}

    @app.post("/api/replay/open", tags=["replay"])
    async def replay_open(name: Annotated[str, Body(embed=True)]) -> dict[str, Any]:
        path = _log_path(name)
        try:
            await asyncio.to_thread(session.open_replay, path)
        except (LogError, ValueError) as exc:
            raise HTTPException(422, str(exc)) from None
        return session.status()

    @app.post("/api/replay/compare", tags=["replay"])
    async def replay_compare(name: Annotated[str, Body(embed=True)]) -> dict[str, Any]:
        path = _log_path(name)
        try:
            await asyncio.to_thread(session.compare_with, path)
        except (LogError, ValueError) as exc:
            raise HTTPException(422, str(exc)) from None
        except SessionError as exc:
            raise HTTPException(409, str(exc)) from None
        return session.status()

    @app.post("/api/replay/{action}", tags=["replay"])
    async def replay_action(
        action: str, t_s: Annotated[float | None, Body(embed=True)] = None
    ) -> dict[str, Any]:
        if action not in ("play", "pause", "seek", "closest"):
            raise HTTPException(404, f"unknown replay action {action!r}")
        if action == "seek" and (t_s is None or not math.isfinite(t_s)):
            raise HTTPException(422, "seek needs a finite t_s")
        return _cmd(session.replay_command, action, t_s)

    @app.post("/api/logs/{name}/refly", tags=["logs"])
    async def refly(name: str, req: ReflyRequest) -> dict[str, Any]:
        if req.law not in GUIDANCE_LAWS:
            raise HTTPException(422, f"unknown law {req.law!r}")
        player = await asyncio.to_thread(_player, name)
        text = scenario_attachment(player.path)
        if not text:
            raise HTTPException(422, f"{name}: no scenario recorded with it")
        try:
            scenario = parse_scenario(text, source=name)
            # the gains it flew (edits included), so the re-fly flies the same sortie
            flown = player.describe()["gains"] or scenario.gains
            scenario = with_changes(scenario, gains={**flown, **(req.gains or {})})
        except (ScenarioError, GainError) as exc:
            raise HTTPException(422, str(exc)) from None
        camera = player.info.camera if player.info.camera in CAMERA_MODES else "projected"
        if req.speed not in SPEEDS:
            raise HTTPException(422, f"speed must be one of {', '.join(SPEEDS)}")
        config = SortieConfig(
            scenario,
            req.law,
            req.seed if req.seed is not None else (player.info.seed or 0),
            camera,
            req.speed,
        )
        _cmd(session.start, config, (player.tt, player.tp))
        return _cmd(session.compare_with, player.path)

    def _cmd(fn, *args):
        try:
            fn(*args)
        except SessionError as exc:
            raise HTTPException(409, str(exc)) from None
        return session.status()

    @app.post("/api/sortie/start", tags=["sortie"])
    async def start(req: StartRequest) -> dict[str, Any]:
        if req.law not in GUIDANCE_LAWS:
            raise HTTPException(
                422, f"unknown law {req.law!r}; choose one of {', '.join(sorted(GUIDANCE_LAWS))}"
            )
        if req.camera not in CAMERA_MODES:
            raise HTTPException(422, f"camera must be one of {', '.join(CAMERA_MODES)}")
        if req.speed not in SPEEDS:
            raise HTTPException(422, f"speed must be one of {', '.join(SPEEDS)}")
        scenario = _scenario_from(req)
        return _cmd(session.start, SortieConfig(scenario, req.law, req.seed, req.camera, req.speed))

    @app.post("/api/sortie/pause", tags=["sortie"])
    async def pause() -> dict[str, Any]:
        return _cmd(session.pause)

    @app.post("/api/sortie/resume", tags=["sortie"])
    async def resume() -> dict[str, Any]:
        return _cmd(session.resume)

    @app.post("/api/sortie/step", tags=["sortie"])
    async def step() -> dict[str, Any]:
        return _cmd(session.step)

    @app.post("/api/sortie/reset", tags=["sortie"])
    async def reset() -> dict[str, Any]:
        return _cmd(session.reset)

    @app.put("/api/sortie/speed", tags=["sortie"])
    async def speed(speed: Annotated[str, Body(embed=True)]) -> dict[str, Any]:
        return _cmd(session.set_speed, speed)

    @app.get("/api/sortie/series", tags=["sortie"])
    async def sortie_series() -> dict[str, Any]:
        """The sortie on screen so far (plot columns and timeline markers), for a page that
        loads mid-sortie; a recorded sortie's are at /api/logs/{name}/series."""
        fn = getattr(session, "series", None)
        if fn is None:
            return {"t_s": [], "columns": {}, "events": []}
        return fn()

    @app.get("/api/status", tags=["sortie"])
    async def status() -> dict[str, Any]:
        return session.status()

    async def _live(action: str) -> dict[str, Any]:
        fn = getattr(session, f"live_{action}", None)
        if fn is None:
            raise HTTPException(409, "simulator mode: there is no live vehicle")
        try:
            ack = await asyncio.to_thread(fn)
        except SessionError as exc:
            raise HTTPException(409, str(exc)) from None
        return {"ack": ack, "status": session.status()}

    @app.post("/api/live/start", tags=["live"])
    async def live_start() -> dict[str, Any]:
        """Send the start command to the onboard computer and wait for its COMMAND_ACK."""
        return await _live("start")

    @app.post("/api/live/abort", tags=["live"])
    async def live_abort() -> dict[str, Any]:
        """Send abort (brake and hold) and wait for the COMMAND_ACK."""
        return await _live("abort")

    return TokenAuthMiddleware(app, token)  # type: ignore[return-value]


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
    ) -> None:
        if no_auth and not is_loopback(host):
            raise ValueError(f"--no-auth is refused on a non-loopback address ({host})")
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
        self.gainsets = GainSetStore((data_dir or default_data_dir()) / "gainsets")
        self.app = create_app(
            self.session,
            self.hub,
            self.token,
            self.viser_port,
            self.gainsets,
            LogIndex(log_dir or Path("logs")),
        )
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

    @property
    def port(self) -> int:
        for srv in getattr(self.server, "servers", []):
            for sock in srv.sockets:
                return sock.getsockname()[1]
        return self.server.config.port

    def url(self) -> str:
        shown = "127.0.0.1" if self.host in ("0.0.0.0", "::") else self.host
        base = f"http://{shown}:{self.port}/"
        return base if self.token is None else f"{base}?token={self.token}"

    def start_in_thread(self, timeout_s: float = 10.0) -> None:
        self._thread = threading.Thread(target=self.server.run, daemon=True)
        self._thread.start()
        deadline = time.monotonic() + timeout_s
        while not self.server.started:
            if time.monotonic() > deadline or not self._thread.is_alive():
                raise RuntimeError("the ground station did not start")
            time.sleep(0.02)

    def run_forever(self) -> None:
        try:
            self.server.run()
        finally:
            self.close()

    def stop(self) -> None:
        self.server.should_exit = True
        if self._thread is not None:
            self._thread.join(timeout=10.0)
        self.close()

    def close(self) -> None:
        self.session.close()
        with contextlib.redirect_stdout(io.StringIO()):
            self.viser.stop()
