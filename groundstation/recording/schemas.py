"""JSON Schemas of the recorded channels. Foxglove recognises its well-known types by schema
name (``foxglove.PoseInFrame`` ...) with ``jsonschema`` encoding and shows them without
plugins; ``peregrine.*`` are ours. Bytes (image data) are base64 strings, as Foxglove's JSON
encoding expects."""

from __future__ import annotations

import json

from onboard import messages

_TIME = {"type": "object", "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}}}
_VEC3 = {"type": "object", "properties": {k: {"type": "number"} for k in "xyz"}}
_QUAT = {"type": "object", "properties": {k: {"type": "number"} for k in "xyzw"}}
_POSE = {"type": "object", "properties": {"position": _VEC3, "orientation": _QUAT}}
_COLOR = {"type": "object", "properties": {k: {"type": "number"} for k in "rgba"}}
_P2 = {"type": "object", "properties": {"x": {"type": "number"}, "y": {"type": "number"}}}
_NUM = {"type": "number"}
_NUMS = {"type": "array", "items": _NUM}


def _obj(title: str, **props) -> dict:
    return {"title": title, "type": "object", "properties": props}


_KIND = {
    "number": _NUM,
    "numbers": _NUMS,
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
    "foxglove.PoseInFrame": _obj(
        "foxglove.PoseInFrame", timestamp=_TIME, frame_id={"type": "string"}, pose=_POSE
    ),
    "foxglove.FrameTransforms": _obj(
        "foxglove.FrameTransforms",
        transforms={
            "type": "array",
            "items": _obj(
                "foxglove.FrameTransform",
                timestamp=_TIME,
                parent_frame_id={"type": "string"},
                child_frame_id={"type": "string"},
                translation=_VEC3,
                rotation=_QUAT,
            ),
        },
    ),
    "foxglove.SceneUpdate": _obj(
        "foxglove.SceneUpdate",
        deletions={"type": "array"},
        entities={
            "type": "array",
            "items": _obj(
                "foxglove.SceneEntity",
                timestamp=_TIME,
                frame_id={"type": "string"},
                id={"type": "string"},
                lifetime=_TIME,
                frame_locked={"type": "boolean"},
                spheres={
                    "type": "array",
                    "items": _obj("foxglove.SpherePrimitive", pose=_POSE, size=_VEC3, color=_COLOR),
                },
                lines={
                    "type": "array",
                    "items": _obj(
                        "foxglove.LinePrimitive",
                        type={"type": "integer"},
                        pose=_POSE,
                        thickness=_NUM,
                        scale_invariant={"type": "boolean"},
                        points={"type": "array", "items": _VEC3},
                        color=_COLOR,
                    ),
                },
            ),
        },
    ),
    "foxglove.CompressedImage": _obj(
        "foxglove.CompressedImage",
        timestamp=_TIME,
        frame_id={"type": "string"},
        data={"type": "string", "contentEncoding": "base64"},
        format={"type": "string"},
    ),
    "foxglove.CameraCalibration": _obj(
        "foxglove.CameraCalibration",
        timestamp=_TIME,
        frame_id={"type": "string"},
        width={"type": "integer"},
        height={"type": "integer"},
        distortion_model={"type": "string"},
        D=_NUMS,
        K=_NUMS,
        R=_NUMS,
        P=_NUMS,
    ),
    "foxglove.ImageAnnotations": _obj(
        "foxglove.ImageAnnotations",
        circles={
            "type": "array",
            "items": _obj(
                "foxglove.CircleAnnotation",
                timestamp=_TIME,
                position=_P2,
                diameter=_NUM,
                thickness=_NUM,
                fill_color=_COLOR,
                outline_color=_COLOR,
            ),
        },
        points={
            "type": "array",
            "items": _obj(
                "foxglove.PointsAnnotation",
                timestamp=_TIME,
                type={"type": "integer"},
                points={"type": "array", "items": _P2},
                outline_color=_COLOR,
                thickness=_NUM,
            ),
        },
    ),
    "foxglove.Log": _obj(
        "foxglove.Log",
        timestamp=_TIME,
        level={"type": "integer"},
        message={"type": "string"},
        name={"type": "string"},
        file={"type": "string"},
        line={"type": "integer"},
    ),
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
