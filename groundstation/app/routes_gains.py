"""``/api/gains`` and ``/api/gainsets``: read, edit (checked against onboard/gains.py, handed
to the session: the simulator's loop at its next tick, or PARAM_SET to the vehicle), reset to
the gains the sortie started from, and named sets on disk."""

from __future__ import annotations

import asyncio
from typing import Annotated, Any

from fastapi import APIRouter, Body, HTTPException

from onboard.gains import GAIN_SPECS, GainError, Gains

from .api_models import GainSetSaved, GainsOut, GainSpecOut
from .gainsets import GainSetError, GainSetStore
from .session import SessionError


def router(session: Any, gainsets: GainSetStore) -> APIRouter:
    r = APIRouter(tags=["gains"])

    def gains_out() -> GainsOut:
        st = session.status()
        return GainsOut(
            values=session.gains.to_dict(),
            specs=[
                GainSpecOut(
                    name=s.name,
                    default=s.default,
                    unit=s.unit,
                    min=s.minimum,
                    max=s.maximum,
                    meaning=s.meaning,
                )
                for s in GAIN_SPECS
            ],
            applied_time_s=st["gains_applied_time_s"],
            pending=st["gains_pending"],
        )

    async def apply(gains: Gains) -> GainsOut:
        try:
            await asyncio.to_thread(session.set_gains, gains)
        except SessionError as exc:
            raise HTTPException(409, str(exc)) from None
        return gains_out()

    @r.get("/api/gains")
    async def get_gains() -> GainsOut:
        return gains_out()

    @r.put("/api/gains")
    async def put_gains(changes: Annotated[dict[str, Any], Body()]) -> GainsOut:
        """Change the named gains (the others keep their values)."""
        try:
            new = session.gains.replace(**changes)
        except (GainError, TypeError) as exc:
            raise HTTPException(422, str(exc)) from None
        return await apply(new)

    @r.post("/api/gains/reset")
    async def reset_gains() -> GainsOut:
        """Back to the gains the sortie started from: the scenario's in the simulator, the
        vehicle's own parameters as first read in live mode."""
        try:
            gains = session.default_gains()
        except SessionError as exc:
            raise HTTPException(409, str(exc)) from None
        return await apply(gains)

    @r.get("/api/gainsets")
    async def list_gainsets() -> list[str]:
        return gainsets.names()

    @r.put("/api/gainsets/{name}")
    async def save_gainset(name: str) -> GainSetSaved:
        try:
            gainsets.save(name, session.gains)
        except GainSetError as exc:
            raise HTTPException(422, str(exc)) from None
        return GainSetSaved(saved=name, names=gainsets.names())

    @r.post("/api/gainsets/{name}/load")
    async def load_gainset(name: str) -> GainsOut:
        try:
            gains = gainsets.load(name)
        except (GainSetError, GainError) as exc:
            raise HTTPException(422, str(exc)) from None
        return await apply(gains)

    return r
