"""Request and response models of the REST API: what /docs shows goes in and comes back. The
option-valued fields are ``Literal``s built from the one declaration of each list, so a bad
law, camera or speed is refused by validation, with the choices in the message."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field

from onboard.enums import GuidanceLaw, codes

from ..scenario import CAMERA_MODES, ESTIMATE_PROFILES
from .session_config import SPEEDS, SortieConfig

LawName = Literal[codes(GuidanceLaw)]  # type: ignore[valid-type]
CameraMode = Literal[CAMERA_MODES]  # type: ignore[valid-type]
Speed = Literal[tuple(SPEEDS)]  # type: ignore[valid-type]
ProfileName = Literal[ESTIMATE_PROFILES]  # type: ignore[valid-type]


class Meta(BaseModel):
    laws: list[str] = Field(description="guidance laws (MAVLink LAW code = index)")
    loop_modes: list[str] = Field(description="interception loop modes (code = index)")
    runtime_states: list[str] = Field(description="onboard runtime states (code = index)")
    outcomes: list[str] = Field(description="simulated sortie outcomes")
    camera_modes: list[str]
    speeds: list[str] = Field(description="simulator speeds: multiples of real time, or max")
    defaults: dict[str, str] = Field(
        description="the value each list starts on, by list name (laws, camera_modes, speeds)"
    )


class StartRequest(BaseModel):
    scenario: str | None = Field(None, description="name of a shipped scenario")
    toml: str | None = Field(None, description="scenario file text (instead of a name)")
    law: LawName = SortieConfig.law
    seed: int = 0
    camera: CameraMode = SortieConfig.camera
    speed: Speed = SortieConfig.speed
    wind_mean_m_s: list[float] | None = Field(None, min_length=3, max_length=3)
    gust_m_s: float | None = Field(None, ge=0.0)
    profile: ProfileName | None = Field(
        None,
        description="state-estimate error profile (default: the scenario's, realistic); "
        "ideal = ideal sensors, analysis only, labelled in the status",
    )


class ReflyRequest(BaseModel):
    law: LawName = SortieConfig.law
    seed: int | None = None
    speed: Speed = SortieConfig.speed
    gains: dict[str, float] | None = None


class SpeedRequest(BaseModel):
    speed: str = Field(description="one of GET /api/meta's speeds; another answers 409")


class ScenarioSummary(BaseModel):
    name: str
    motion: str
    description: str


class ScenarioText(BaseModel):
    name: str
    toml: str


class ScenarioCheck(BaseModel):
    ok: bool
    name: str
    motion: str


class GainSpecOut(BaseModel):
    name: str
    default: float
    unit: str
    min: float
    max: float
    meaning: str
    group: str = Field(description="the gains panel's group (onboard/gains.py)")


class GainsOut(BaseModel):
    values: dict[str, float] = Field(description="the gains the session holds, by name")
    specs: list[GainSpecOut]
    applied_time_s: float | None = Field(
        description="sortie time at which the last edit took effect (None: not yet)"
    )
    pending: bool = Field(description="an edit sent and not yet in force")
    refused: dict[str, str] = Field(
        default_factory=dict,
        description="with ?valid_only=true: each refused edit and why (the others applied)",
    )


class GainSetSaved(BaseModel):
    saved: str
    names: list[str]


class Status(BaseModel):
    """The session's status (also in every telemetry message); mode-specific parts (``dkf``,
    ``live``, ``intercept_time_s``) appear when they apply."""

    model_config = ConfigDict(extra="allow")

    state: str = Field(description="idle | running | paused | finished | replay | live")
    scenario: str | None
    law: str | None
    seed: int | str | None
    camera: str | None
    profile: str | None = Field(
        default=None, description="state-estimate error profile; ideal = ideal sensors"
    )
    speed: str
    time_s: float
    outcome: str | None
    miss_m: float | None
    loop_rate_hz: float
    gains_applied_time_s: float | None
    gains_pending: bool
    real_time_ratio: float | None
    scene_errors: int
    recording: dict[str, Any] | None
    replay: dict[str, Any] | None


class LiveAck(BaseModel):
    ack: dict[str, Any] = Field(description="the command and the vehicle's COMMAND_ACK result")
    status: Status


class Deleted(BaseModel):
    deleted: str
