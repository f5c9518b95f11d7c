"""``/api/gains`` and ``/api/gainsets``: read, edit (checked against onboard/gains.py, handed
to the session: the simulator's loop at its next tick, or PARAM_SET to the vehicle), reset to
the gains the sortie started from, and named sets on disk."""

from __future__ import annotations

import asyncio
from typing import Annotated, Any

from fastapi import APIRouter, Body, HTTPException
from fastapi.responses import Response

from onboard.gains import GAIN_SPECS, GainError, Gains

from .api_models import GainSetSaved, GainsOut, GainSpecOut
from .gainsets import GainSetError, GainSetStore
from .session import SessionError, SimSession

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


def _group(name: str) -> str:
    return GAIN_GROUPS.get(name, "other")


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
                    group=_group(s.name),
                )
                for s in sorted(GAIN_SPECS, key=lambda s: _GROUP_ORDER.index(_group(s.name)))
            ],
            applied_time_s=st["gains_applied_time_s"],
            pending=st["gains_pending"],
        )

    async def apply(gains: Gains, source: str | None = None) -> GainsOut:
        try:
            if source is not None and isinstance(session, SimSession):
                await asyncio.to_thread(session.set_gains, gains, source)
            else:
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
        """Drop the operator's edits: back to the gain set in force (the defaults, the
        scenario's [gains] or the loaded gain set) in the simulator, the vehicle's own
        parameters as first read in live mode."""
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
        return await apply(gains, f"gain set {name}")

    @r.get("/api/gainsets/{name}/file")
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

    @r.post("/api/gainsets/upload")
    async def upload_gainset(
        name: Annotated[str, Body()], toml: Annotated[str, Body()]
    ) -> GainSetSaved:
        """Save an uploaded gain set file (``name = value`` lines) under ``name``, checked
        first: a bad file changes nothing."""
        try:
            gainsets.save_text(name, toml)
        except (GainSetError, GainError) as exc:
            raise HTTPException(422, str(exc)) from None
        return GainSetSaved(saved=name, names=gainsets.names())

    return r
