"""``/api/gains`` and ``/api/gainsets``: read, edit (checked against onboard/gains.py, handed
to the session: the simulator's loop at its next tick, or PARAM_SET to the vehicle), reset to
the gains the sortie started from, and named sets on disk."""

from __future__ import annotations

import asyncio
from typing import Annotated, Any

from fastapi import APIRouter, Body, HTTPException
from fastapi.responses import JSONResponse, Response

from onboard.gains import GAIN_GROUPS, GAIN_SPECS, GainError, Gains

from .api_models import GainSetSaved, GainsOut, GainSpecOut
from .errors import SessionError
from .gainsets import GainSetError, GainSetStore
from .protocol import Session


def check_each(gains: Gains, changes: dict[str, Any]) -> tuple[dict[str, Any], dict[str, str]]:
    """Each change checked on its own against ``gains``: (the valid ones, name -> why refused
    for every other)."""
    valid, refused = {}, {}
    for k, v in changes.items():
        try:
            gains.replace(**{k: v})
        except (GainError, TypeError) as exc:
            refused[k] = str(exc)
        else:
            valid[k] = v
    return valid, refused


def router(session: Session, gainsets: GainSetStore) -> APIRouter:
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
                    group=s.group,
                )
                for s in sorted(GAIN_SPECS, key=lambda s: GAIN_GROUPS.index(s.group))
            ],
            applied_time_s=st["gains_applied_time_s"],
            pending=st["gains_pending"],
        )

    async def apply(gains: Gains, source: str | None = None) -> GainsOut:
        try:
            await asyncio.to_thread(session.set_gains, gains, source)
        except SessionError as exc:
            raise HTTPException(409, str(exc)) from None
        return gains_out()

    @r.get("/api/gains")
    async def get_gains() -> GainsOut:
        return gains_out()

    @r.put("/api/gains", response_model=GainsOut)
    async def put_gains(
        changes: Annotated[dict[str, Any], Body()], valid_only: bool = False
    ) -> GainsOut | JSONResponse:
        """Change the named gains (the others keep their values). A refused value (unknown
        name, not a number, out of range) refuses them all (422 naming every one), unless
        ``valid_only``: then the valid ones are applied and ``refused`` says why the others
        were not."""
        valid, refused = check_each(session.gains, changes)
        if refused and not valid_only:  # nothing applied; every refusal named
            return JSONResponse(
                {"detail": "; ".join(refused.values()), "refused": refused}, status_code=422
            )
        if not valid:
            out = gains_out()
        else:
            out = await apply(session.gains.replace(**valid))
        out.refused = refused
        return out

    @r.post("/api/gains/reset")
    async def reset_gains() -> GainsOut:
        """Drop the operator's edits: back to the gain set in force (the defaults, the
        scenario's [gains] or the loaded gain set) in the simulator, the vehicle's own
        parameters as first read in live mode."""
        try:
            await asyncio.to_thread(session.reset_edits)
        except SessionError as exc:
            raise HTTPException(409, str(exc)) from None
        return gains_out()

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
        first: a bad file changes nothing and is answered 422 with every problem
        (``problems``)."""
        try:
            gainsets.save_text(name, toml)
        except GainSetError as exc:
            problems = [{"message": m} for m in exc.problems]  # objects, as every 422's
            return JSONResponse({"detail": str(exc), "problems": problems}, status_code=422)
        return GainSetSaved(saved=name, names=gainsets.names())

    return r
