"""``/api/logs`` and ``/api/replay``: the recorded sorties (list, inspect, download, delete
with confirmation), replay and compare in the dashboard, and re-fly with another law."""

from __future__ import annotations

import asyncio
import math
from pathlib import Path
from typing import Annotated, Any

from fastapi import APIRouter, Body, HTTPException
from fastapi.responses import FileResponse

from onboard.gains import GainError, Gains

from ..recording.reader import LogError, LogIndex
from ..scenario import CAMERA_MODES, ScenarioError, parse_scenario
from .api_models import Deleted, ReflyRequest, Status
from .errors import SessionError
from .protocol import Session
from .replay import OVERLAY_MAX, ReplayPlayer, overlay_entry
from .routes_gains import check_each
from .routes_sortie import command
from .session_config import SortieConfig


def router(session: Session, logs: LogIndex) -> APIRouter:
    r = APIRouter()

    def log_path(name: str) -> Path:
        try:
            path = logs.resolve(name)
        except LogError as exc:
            raise HTTPException(400, str(exc)) from None
        if not path.is_file():
            raise HTTPException(404, f"no recorded sortie named {name!r}")
        return path

    def player(name: str) -> ReplayPlayer:
        try:
            return ReplayPlayer(log_path(name), name)
        except (LogError, ValueError) as exc:
            raise HTTPException(422, str(exc)) from None

    @r.get("/api/logs", tags=["logs"])
    async def list_logs(folder: str = "") -> list[dict[str, Any]]:
        """The sorties recorded in ``folder``, a subfolder of the log folder (a campaign's
        ``--log logs/NAME``; "" the log folder itself). Names are relative to the log folder."""
        try:
            return await asyncio.to_thread(logs.list, folder)
        except LogError as exc:
            raise HTTPException(400, str(exc)) from None

    @r.get("/api/logfolders", tags=["logs"])
    async def log_folders() -> list[str]:
        """The log folder ("") and its subfolders that hold recorded sorties."""
        return await asyncio.to_thread(logs.folders)

    # a log's name may hold its subfolder ("static-n10/x.mcap"): the routes with a suffix
    # come before the bare one, which would otherwise take "x.mcap/series" for a name
    @r.get("/api/logs/{name:path}/series", tags=["logs"])
    async def log_series(name: str) -> dict[str, Any]:
        """The whole recorded sortie for the plots: ``t_s``, the dashboard's plot columns,
        every numeric /control field, the timeline's markers and who the sortie is."""
        return (await asyncio.to_thread(player, name)).series()

    @r.get("/api/logs/{name:path}/file", tags=["logs"])
    async def download_log(name: str) -> FileResponse:
        path = log_path(name)
        return FileResponse(path, media_type="application/octet-stream", filename=path.name)

    @r.get("/api/logs/{name:path}", tags=["logs"])
    async def log_info(name: str) -> dict[str, Any]:
        log_path(name)  # 400 for a bad name, 404 for none
        try:
            return {**logs.info(name).to_json_dict(), "name": name}
        except LogError as exc:
            raise HTTPException(422, str(exc)) from None

    @r.delete("/api/logs/{name:path}", tags=["logs"])
    async def delete_log(name: str, confirm: str = "") -> Deleted:
        path = log_path(name)
        if confirm != name:
            raise HTTPException(400, "to delete, repeat the file name in ?confirm=")
        rec = session.recording
        if rec is not None and rec["file"] == name and not rec["closed"]:
            raise HTTPException(409, "this sortie is still being recorded")
        path.unlink()
        return Deleted(deleted=name)

    @r.get("/api/overlay", tags=["logs"])
    async def overlay(names: str) -> list[dict[str, Any]]:
        """Up to OVERLAY_MAX recorded sorties (``names``: comma-separated) for the overlay
        page: each one's legend, outcome, plot columns and position relative to the target."""
        wanted = [n for n in names.split(",") if n]
        if not 1 <= len(wanted) <= OVERLAY_MAX:
            raise HTTPException(422, f"overlay 1 to {OVERLAY_MAX} sorties, not {len(wanted)}")
        paths = [log_path(n) for n in wanted]

        def read() -> list[dict[str, Any]]:
            out = []
            for path, name in zip(paths, wanted, strict=True):
                try:
                    out.append(overlay_entry(path, name))
                except (LogError, ValueError) as exc:
                    raise HTTPException(422, f"{name}: {exc}") from None
            return out

        return await asyncio.to_thread(read)

    @r.post("/api/replay/open", tags=["replay"])
    async def replay_open(name: Annotated[str, Body(embed=True)]) -> Status:
        path = log_path(name)
        try:
            await asyncio.to_thread(session.open_replay, path, name)
        except (LogError, ValueError) as exc:
            raise HTTPException(422, str(exc)) from None
        return session.status()

    @r.post("/api/replay/compare", tags=["replay"])
    async def replay_compare(name: Annotated[str, Body(embed=True)]) -> Status:
        path = log_path(name)
        try:
            await asyncio.to_thread(session.compare_with, path, name)
        except (LogError, ValueError) as exc:
            raise HTTPException(422, str(exc)) from None
        except SessionError as exc:
            raise HTTPException(409, str(exc)) from None
        return session.status()

    @r.post("/api/replay/{action}", tags=["replay"])
    async def replay_action(
        action: str, t_s: Annotated[float | None, Body(embed=True)] = None
    ) -> Status:
        """``play``, ``pause``, ``seek`` (to ``t_s``) or ``closest`` (closest approach)."""
        if action not in ("play", "pause", "seek", "closest"):
            raise HTTPException(404, f"unknown replay action {action!r}")
        if action == "seek" and (t_s is None or not math.isfinite(t_s)):
            raise HTTPException(422, "seek needs a finite t_s")
        return command(session, session.replay_command, action, t_s)

    @r.post("/api/logs/{name:path}/refly", tags=["logs"])
    async def refly(name: str, req: ReflyRequest) -> Status:
        """Fly the recorded target track again (another law, seed or gains), recorded, with
        the old sortie overlaid."""
        rp = await asyncio.to_thread(player, name)
        text = rp.scenario_text
        if not text:
            raise HTTPException(422, f"{name}: no scenario recorded with it")
        try:
            scenario = parse_scenario(text, source=name)
        except ScenarioError as exc:
            raise HTTPException(422, str(exc)) from None
        # the gains it flew (edits included) with the form's changes: this sortie's only
        recorded = rp.describe()["gains"] or scenario.gains
        try:
            flown = Gains.from_mapping(recorded, source=f"{name}: recorded gains")
        except GainError as exc:
            raise HTTPException(422, str(exc)) from None
        _valid, refused = check_each(flown, req.gains or {})
        if refused:
            raise HTTPException(422, "; ".join(refused.values()))
        gains = flown.replace(**(req.gains or {}))
        camera = rp.info.camera if rp.info.camera in CAMERA_MODES else "projected"
        seed = req.seed if req.seed is not None else (rp.info.seed or 0)
        config = SortieConfig(scenario, req.law, seed, camera, req.speed)
        command(session, session.start, config, (rp.tt, rp.tp), gains, f"re-fly of {name}")
        return command(session, session.compare_with, rp.path, rp.name)

    return r
