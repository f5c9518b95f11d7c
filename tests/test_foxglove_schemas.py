"""Every foxglove.* message a recording holds is valid against Foxglove's official JSON Schema
(the files of @foxglove/schemas, embedded unmodified), and those files agree, field for field,
with the message descriptors of the foxglove-sdk package the project depends on."""

from __future__ import annotations

import json

import pytest
from jsonschema import Draft202012Validator
from mcap.reader import make_reader

from groundstation.recording.writer import SortieRecorder
from groundstation.scenario import load_scenario
from groundstation.sim.simulation import Simulation
from onboard.channels import official_schemas
from onboard.channels.official_schemas import official_schema
from onboard.channels.schemas import CHANNELS, SCHEMAS

PER_TOPIC = 300  # messages validated per channel (all of the slow ones)


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    rec = SortieRecorder(tmp_path_factory.mktemp("logs"), mode="local")
    sim = Simulation(
        load_scenario("cv-top-to-bottom"), camera_mode="rendered", keep_records=False,
        observers=[rec],
    )  # fmt: skip
    sim.run()
    assert rec.closed and rec.error is None
    return rec.path


def test_every_channel_message_is_valid_against_its_schema(recording):
    seen: dict[str, int] = {}
    detections = 0
    with open(recording, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            if schema.name.startswith("foxglove."):
                # the file embeds the official schema byte for byte in meaning
                assert json.loads(schema.data) == official_schema(schema.name)
            if seen.get(channel.topic, 0) >= PER_TOPIC:
                continue
            seen[channel.topic] = seen.get(channel.topic, 0) + 1
            doc = json.loads(message.data)
            errors = list(Draft202012Validator(json.loads(schema.data)).iter_errors(doc))
            assert not errors, (channel.topic, [e.message for e in errors[:3]])
            if channel.topic == "/camera/annotations" and doc["points"]:
                detections += 1
    assert set(seen) == {topic for topic, _ in CHANNELS}  # every channel checked
    assert detections > 0  # the detection marker (a PointsAnnotation) was among them


def test_a_message_missing_a_required_field_is_refused():
    """The check can fail: the cut-down messages the files once had are invalid."""
    v = Draft202012Validator(official_schema("foxglove.ImageAnnotations"))
    assert not list(v.iter_errors({"circles": [], "points": [], "texts": []}))
    assert [e.message for e in v.iter_errors({"circles": [], "points": []})] == [
        "'texts' is a required property"
    ]


def test_embedded_schemas_are_the_official_files():
    for _, name in CHANNELS:
        if name.startswith("foxglove."):
            assert SCHEMAS[name] is official_schema(name)
            assert SCHEMAS[name]["title"] == name
    with pytest.raises(KeyError):
        official_schema("foxglove.NotAType")


def _proto_fields(desc) -> dict:
    """Field names of a protobuf message, nested messages expanded (Timestamp/Duration as
    Foxglove's JSON {sec, nsec})."""
    out = {}
    for f in desc.fields:
        m = f.message_type
        if m is None or m.full_name.startswith("google.protobuf."):
            out[f.name] = None
        else:
            out[f.name] = _proto_fields(m)
    return out


def _json_fields(schema: dict) -> dict:
    out = {}
    for name, prop in schema["properties"].items():
        item = prop.get("items", prop) if prop.get("type") == "array" else prop
        is_msg = item.get("type") == "object" and str(item.get("title", "")).startswith("foxglove.")
        out[name] = _json_fields(item) if is_msg else None
    return out


@pytest.mark.parametrize("stem", official_schemas.TYPES)
def test_official_files_agree_with_the_foxglove_sdk_descriptors(stem):
    """The JSON Schema copies and the installed foxglove-sdk describe the same messages: a
    newer SDK with changed types fails here until the copies are refreshed (--update)."""
    pytest.importorskip("google.protobuf")
    import foxglove.messages
    from google.protobuf import descriptor_pb2, descriptor_pool

    schema = getattr(foxglove.messages, stem).get_schema()
    assert schema.encoding == "protobuf" and schema.name == f"foxglove.{stem}"
    fds = descriptor_pb2.FileDescriptorSet.FromString(bytes(schema.data))
    pool = descriptor_pool.DescriptorPool()
    for fd in fds.file:
        pool.Add(fd)
    proto = _proto_fields(pool.FindMessageTypeByName(schema.name))
    assert _json_fields(official_schema(f"foxglove.{stem}")) == proto
