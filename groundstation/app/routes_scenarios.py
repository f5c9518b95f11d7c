"""``/api/meta`` and ``/api/scenarios``: what the page can choose from (read-only)."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Body, HTTPException

from onboard import enums

from ..scenario import CAMERA_MODES, load_scenario, parse_scenario, scenario_toml, shipped_scenarios
from .api_models import Meta, ScenarioCheck, ScenarioSummary, ScenarioText
from .session_config import SPEEDS, SortieConfig


def router() -> APIRouter:
    r = APIRouter()

    @r.get("/api/meta", tags=["meta"])
    async def get_meta() -> Meta:
        """The option lists the page offers, from their one declaration (onboard/enums.py,
        the simulator's camera modes, the session's speeds)."""
        return Meta(
            **enums.meta(),
            camera_modes=list(CAMERA_MODES),
            speeds=list(SPEEDS),
            defaults={
                "laws": SortieConfig.law,
                "camera_modes": SortieConfig.camera,
                "speeds": SortieConfig.speed,
            },
        )

    @r.get("/api/scenarios", tags=["scenarios"])
    async def list_scenarios() -> list[ScenarioSummary]:
        out = []
        for p in shipped_scenarios():
            s = load_scenario(p)
            out.append(
                ScenarioSummary(name=s.name, motion=s.target.motion, description=s.description)
            )
        return out

    @r.get("/api/scenarios/{name}", tags=["scenarios"])
    async def get_scenario(name: str) -> ScenarioText:
        names = {p.stem: p for p in shipped_scenarios()}
        if name not in names:
            raise HTTPException(404, f"unknown scenario {name!r}")
        # the file, with the [estimate] table that applies when the file has none
        return ScenarioText(name=name, toml=scenario_toml(load_scenario(names[name])))

    @r.post("/api/scenarios/validate", tags=["scenarios"])
    async def validate_scenario(toml: Annotated[str, Body(embed=True)]) -> ScenarioCheck:
        s = parse_scenario(toml, source="uploaded scenario")  # 422 lists every problem
        return ScenarioCheck(ok=True, name=s.name, motion=s.target.motion)

    return r
