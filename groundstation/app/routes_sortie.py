"""``/api/sortie/*``, ``/api/status`` and ``/api/live/*``: start and steer the simulated
sortie, or command the live vehicle (every route that changes behaviour sits behind the token,
as all routes do)."""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Any

from fastapi import APIRouter, HTTPException

from ..scenario import load_scenario, parse_scenario, shipped_scenarios
from ..sim.profiles import with_profile
from .api_models import LiveAck, SpeedRequest, StartRequest, Status
from .errors import SessionError
from .protocol import Session
from .session_config import SortieConfig, with_wind


def command(session: Session, fn: Callable[..., Any], *args: Any) -> dict[str, Any]:
    """Carry out a session command; one that cannot be carried out now answers 409."""
    try:
        fn(*args)
    except SessionError as exc:
        raise HTTPException(409, str(exc)) from None
    return session.status()


def scenario_from(req: StartRequest):
    if (req.scenario is None) == (req.toml is None):
        raise HTTPException(422, "give exactly one of 'scenario' (a name) or 'toml' (file text)")
    # a ScenarioError is answered 422 with every problem located (server._declare_errors)
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
    return with_profile(scenario, req.profile)


def router(session: Session) -> APIRouter:
    r = APIRouter()

    @r.post("/api/sortie/start", tags=["sortie"])
    async def start(req: StartRequest) -> Status:
        scenario = scenario_from(req)
        config = SortieConfig(scenario, req.law, req.seed, req.camera, req.speed)
        return command(session, session.start, config)

    @r.post("/api/sortie/pause", tags=["sortie"])
    async def pause() -> Status:
        return command(session, session.pause)

    @r.post("/api/sortie/resume", tags=["sortie"])
    async def resume() -> Status:
        return command(session, session.resume)

    @r.post("/api/sortie/step", tags=["sortie"])
    async def step() -> Status:
        return command(session, session.step)

    @r.post("/api/sortie/reset", tags=["sortie"])
    async def reset() -> Status:
        return command(session, session.reset)

    @r.put("/api/sortie/speed", tags=["sortie"])
    async def speed(req: SpeedRequest) -> Status:
        return command(session, session.set_speed, req.speed)

    @r.get("/api/sortie/series", tags=["sortie"])
    async def sortie_series() -> dict[str, Any]:
        """The sortie on screen so far (plot columns and timeline markers), for a page that
        loads mid-sortie; a recorded sortie's are at /api/logs/{name}/series."""
        return session.series()

    @r.get("/api/status", tags=["sortie"])
    async def status() -> Status:
        return session.status()

    async def live(action: str) -> dict[str, Any]:
        try:
            ack = await asyncio.to_thread(session.live_command, action)
        except SessionError as exc:
            raise HTTPException(409, str(exc)) from None
        return {"ack": ack, "status": session.status()}

    @r.post("/api/live/start", tags=["live"])
    async def live_start() -> LiveAck:
        """Send the start command to the onboard computer and wait for its COMMAND_ACK."""
        return await live("start")

    @r.post("/api/live/abort", tags=["live"])
    async def live_abort() -> LiveAck:
        """Send abort (brake and hold) and wait for the COMMAND_ACK."""
        return await live("abort")

    return r
