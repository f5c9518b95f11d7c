"""JSON Schemas of the recorded channels. Foxglove recognises its well-known types by schema
name (``foxglove.PoseInFrame`` ...) with ``jsonschema`` encoding and shows them without
plugins: those are Foxglove's official schemas (:mod:`.official_schemas`), embedded as
published; ``peregrine.*`` are ours. Bytes (image data) are base64 strings, as Foxglove's JSON
encoding expects."""

from __future__ import annotations

import json

from onboard import messages

from . import official_schemas
from .official_schemas import official_schema

_NUM = {"type": "number"}
_NUMS = {"type": "array", "items": _NUM}


def _obj(title: str, **props) -> dict:
    return {"title": title, "type": "object", "properties": props}


_KIND = {  # null: a value the loop has not got (before acquisition, a lost target)
    "number": {"type": ["number", "null"]},
    "numbers": {"type": ["array", "null"], "items": _NUM},
    "string": {"type": "string"},
    "boolean": {"type": "boolean"},
}


def _message(title: str, fields: tuple[messages.MessageField, ...]) -> dict:
    """A schema from its one definition in onboard/messages.py (units and meanings kept)."""
    return _obj(
        title,
        **{f.name: {**_KIND[f.kind], "description": f"{f.meaning} [{f.unit}]"} for f in fields},
    )


SCHEMAS: dict[str, dict] = {
    **{f"foxglove.{t}": official_schema(f"foxglove.{t}") for t in official_schemas.TYPES},
    "peregrine.Control": _message("peregrine.Control", messages.CONTROL),
    "peregrine.Dkf": _message("peregrine.Dkf", messages.DKF),
    "peregrine.Gains": {
        "title": "peregrine.Gains",
        "type": "object",
        "additionalProperties": {"type": "number"},
    },
}


def schema_bytes(name: str) -> bytes:
    return json.dumps(SCHEMAS[name], separators=(",", ":")).encode()


# (topic, schema name) of every channel a sortie recording has
CHANNELS: tuple[tuple[str, str], ...] = (
    ("/world/vehicle", "foxglove.PoseInFrame"),
    ("/world/target", "foxglove.PoseInFrame"),
    ("/tf", "foxglove.FrameTransforms"),
    ("/scene", "foxglove.SceneUpdate"),
    ("/camera/image", "foxglove.CompressedImage"),
    ("/camera/calibration", "foxglove.CameraCalibration"),
    ("/camera/annotations", "foxglove.ImageAnnotations"),
    ("/control", "peregrine.Control"),
    ("/dkf", "peregrine.Dkf"),
    ("/gains", "peregrine.Gains"),
    ("/events", "foxglove.Log"),
)
