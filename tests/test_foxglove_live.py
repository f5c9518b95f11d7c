"""Foxglove live: a WebSocket client speaking Foxglove's WebSocket protocol (subprotocol
``foxglove.sdk.v1``, the SDK's name for ``foxglove.websocket.v1``; both offered) sees the
recording's channels advertised (same topics, schema names and schemas) and receives a
sortie's messages with the recorder's content."""

from __future__ import annotations

import asyncio
import json
import struct
import time
from types import SimpleNamespace

import pytest

from groundstation.scenario import load_scenario
from groundstation.sim.simulation import Simulation
from onboard.channels.schemas import CHANNELS, SCHEMAS, schema_bytes
from onboard.frames import FrameList

websockets = pytest.importorskip("websockets")
live_mod = pytest.importorskip("onboard.channels.live")

SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
MESSAGE_DATA = 0x01  # binary opcode: subscription id u32, log time u64, payload


async def _session(live, run_sortie) -> tuple[dict, list[dict]]:
    async with websockets.connect(
        live.url(), subprotocols=SUBPROTOCOLS, open_timeout=10, close_timeout=1
    ) as ws:
        advertised: dict[str, dict] = {}
        while len(advertised) < len(CHANNELS):
            msg = json.loads(await asyncio.wait_for(ws.recv(), 10))
            if msg["op"] == "advertise":
                advertised.update({c["topic"]: c for c in msg["channels"]})
        sub = advertised["/world/vehicle"]["id"]
        await ws.send(
            json.dumps({"op": "subscribe", "subscriptions": [{"id": 7, "channelId": sub}]})
        )
        await asyncio.sleep(0.2)  # the server takes the subscription before the sortie
        sortie = asyncio.create_task(asyncio.to_thread(run_sortie))
        got: list[dict] = []
        while len(got) < 3:
            data = await asyncio.wait_for(ws.recv(), 20)
            if isinstance(data, bytes) and data[0] == MESSAGE_DATA:
                sub_id, _log_ns = struct.unpack_from("<IQ", data, 1)
                assert sub_id == 7
                got.append(json.loads(data[13:]))
        await sortie
        return advertised, got


def test_live_channels_equal_the_recordings_and_messages_arrive():
    live = live_mod.FoxgloveLive(port=0)
    try:
        assert live.port > 0 and live.url().startswith("ws://127.0.0.1:")
        frames = FrameList()

        def run_sortie():
            sim = Simulation(
                load_scenario("static-ahead-20m"), keep_records=False,
                observers=[live.observer(), frames],
            )  # fmt: skip
            sim.run()

        advertised, got = asyncio.run(_session(live, run_sortie))
    finally:
        live.stop()
    assert {t: c["schemaName"] for t, c in advertised.items()} == dict(CHANNELS)
    for topic, name in CHANNELS:
        c = advertised[topic]
        assert c["encoding"] == "json" and c["schemaEncoding"] == "jsonschema"
        assert json.loads(c["schema"]) == json.loads(schema_bytes(name))
    # each vehicle pose is the frame of the same time, as the recorder writes it
    t0 = frames.info.t0_s
    by_time = {round((f.time_s - t0) * 1e9): f for f in frames.frames}
    for msg in got:
        assert msg["frame_id"] == "world"
        ns = msg["timestamp"]["sec"] * 1_000_000_000 + msg["timestamp"]["nsec"]
        pos = msg["pose"]["position"]
        frame = by_time[ns]
        assert (pos["x"], pos["y"], pos["z"]) == pytest.approx(frame.vehicle_p_enu_m, abs=1e-3)
    times = [m["timestamp"]["sec"] * 1e9 + m["timestamp"]["nsec"] for m in got]
    assert times == sorted(times) and len(set(times)) == 3


def test_live_refuses_a_port_in_use():
    live = live_mod.FoxgloveLive(port=0)
    try:
        with pytest.raises(Exception, match=r"(?i)address|in use|bind"):
            live_mod.FoxgloveLive(port=live.port)
    finally:
        live.stop()


def test_the_simulator_session_publishes_to_foxglove_and_records(tmp_path):
    """serve --foxglove: each sortie the operator starts is observed by the recorder and by
    a Foxglove publisher (the recorder's channel builder over a FoxgloveSink)."""
    from groundstation.app.session import SimSession, SortieConfig
    from groundstation.recording.writer import SortieRecorder
    from onboard.channels.builder import ChannelBuilder

    live = live_mod.FoxgloveLive(port=0)
    session = SimSession(log_dir=tmp_path)
    session.foxglove = live
    try:
        session.start(SortieConfig(load_scenario("static-ahead-20m")))
        kinds = [(type(o), type(o._given_sink)) for o in session.sim.observers]
        assert kinds == [(SortieRecorder, type(None)), (ChannelBuilder, live_mod.FoxgloveSink)]
    finally:
        session.close()
        live.stop()


def test_serve_options_are_checked(capsys):
    from groundstation.cli import main

    for argv, needle in (
        (["serve", "--foxglove", "127.0.0.1:99999"], "argument --foxglove: '127.0.0.1:99999'"),
        (["serve", "--foxglove", ":8765"], "argument --foxglove: ':8765': no host"),
        (["serve", "--video", "70000"], "argument --video: '70000': the port must be"),
        (["serve", "--video", "5600"], "--video is for live mode (with --mavlink)"),
    ):
        with pytest.raises(SystemExit) as exc:
            code = main(argv)
            raise SystemExit(code)
        err = capsys.readouterr().err
        assert exc.value.code == 2 and needle in err, (argv, err)


def test_a_live_mode_sortie_publishes_what_it_records(tmp_path):
    """serve --mavlink --foxglove: the live recording's frames go to the file and to Foxglove
    through the same recorder, at the live recording's rates."""
    from groundstation.app.live_recording import LiveRecording

    frames = FrameList()
    Simulation(load_scenario("static-ahead-20m"), keep_records=False, observers=[frames]).run()
    live = live_mod.FoxgloveLive(port=0)
    published: list[int] = []
    live.publish = lambda ti, data: published.append(ti)  # count what reaches the server
    live.channels = [SimpleNamespace(has_sinks=lambda: True) for _ in CHANNELS]  # all wanted
    try:
        rec = LiveRecording(tmp_path, frames.info, foxglove=live)
        for f in frames.frames[:100]:
            rec.record(f)
        rec.finish("HIT", "test")
    finally:
        live.stop()
    file_rec, fox = rec.observers
    assert file_rec.path.exists() and file_rec.error is None and fox.path is None
    assert (fox.record_every, fox.annotate_every) == (file_rec.record_every, 1)
    topics = {CHANNELS[ti][0] for ti in published}
    assert {"/world/vehicle", "/control", "/dkf", "/events", "/camera/annotations"} <= topics


# ---------------------------------------------------------------------- onboard run --foxglove
async def _collect_onboard(rig, url: str) -> tuple[dict, dict[str, list[dict]]]:
    """Connect (retrying while ``onboard run`` starts), subscribe to every channel, rebuild
    the loop once (a new sortie: calibration and gains again), start the intercept and
    collect until every channel the vehicle can fill has arrived with a tracked target."""
    from onboard.link.px4 import mavlink

    end = time.monotonic() + 30
    while True:
        try:
            ws = await websockets.connect(
                url, subprotocols=SUBPROTOCOLS, open_timeout=5, close_timeout=1
            )
            break
        except OSError:
            rig.check_alive()
            if time.monotonic() > end:
                raise
            await asyncio.sleep(0.2)
    async with ws:
        advertised: dict[str, dict] = {}
        while len(advertised) < len(CHANNELS):
            msg = json.loads(await asyncio.wait_for(ws.recv(), 10))
            if msg["op"] == "advertise":
                advertised.update({c["topic"]: c for c in msg["channels"]})
        by_sub = {k: c["topic"] for k, c in enumerate(advertised.values())}
        subs = [{"id": k, "channelId": c["id"]} for k, c in enumerate(advertised.values())]
        await ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
        got: dict[str, list[dict]] = {}

        async def until(pred, timeout_s: float, what: str) -> None:
            deadline = time.monotonic() + timeout_s
            while not pred():
                if time.monotonic() > deadline:
                    raise AssertionError(f"no {what}: got {sorted(got)}\n{rig.logs()}")
                try:
                    data = await asyncio.wait_for(ws.recv(), 0.2)
                except TimeoutError:
                    data = None
                rig.pump()
                if isinstance(data, bytes) and data[0] == MESSAGE_DATA:
                    sub_id, _ = struct.unpack_from("<IQ", data, 1)
                    got.setdefault(by_sub[sub_id], []).append(json.loads(data[13:]))

        # joining mid-sortie: the calibration and gains (sent once a sortie) come again
        await until(
            lambda: {"/control", "/camera/calibration", "/gains"} <= set(got),
            20,
            "the running loop's channels",
        )
        rig.wait_text("target in view")
        # a law parameter (its value unchanged) rebuilds the loop: a new sortie on Foxglove
        n = len(rig.texts)
        assert rig.param_set("PRG_LAW", 0.0) == 0.0
        await until(lambda: len(got["/camera/calibration"]) >= 2, 10, "a new sortie")
        rig.wait_text("target in view", after=n)
        assert rig.start() == mavlink.MAV_RESULT_ACCEPTED
        await until(
            lambda: (
                any(m["acquired"] for m in got.get("/dkf", []))
                and any(m["points"] for m in got.get("/camera/annotations", []))
                and "/camera/image" in got
                and len(got["/control"]) >= 50
            ),  # a second of the loop's ticks, tracking
            15,
            "a tracked target",
        )
        return advertised, got


def test_onboard_run_publishes_the_recordings_channels_against_sitl(tmp_path):
    """``onboard run --foxglove`` against ``groundstation sitl``: a Foxglove client sees the
    recording's channels advertised (topics, schema names, schemas) and every message
    received validates against its schema (foxglove.* against Foxglove's official ones)."""
    import socket

    from jsonschema import Draft202012Validator

    from onboard.channels.official_schemas import official_schema

    from .sitl_rig import Rig, free_port

    port = free_port(socket.SOCK_STREAM)
    rig = Rig(tmp_path, onboard_args=("--foxglove", str(port)))
    try:
        advertised, got = asyncio.run(_collect_onboard(rig, f"ws://127.0.0.1:{port}"))
    finally:
        stats = rig.close()
    assert {t: c["schemaName"] for t, c in advertised.items()} == dict(CHANNELS)
    for topic, name in CHANNELS:
        c = advertised[topic]
        assert c["encoding"] == "json" and c["schemaEncoding"] == "jsonschema"
        assert json.loads(c["schema"]) == json.loads(schema_bytes(name))
    # no target position onboard: every other channel arrived
    assert set(got) == {t for t, _ in CHANNELS} - {"/world/target", "/scene"}
    names = dict(CHANNELS)
    for topic, msgs in got.items():
        name = names[topic]
        schema = official_schema(name) if name.startswith("foxglove.") else SCHEMAS[name]
        v = Draft202012Validator(schema)
        for m in msgs:
            errors = [e.message for e in v.iter_errors(m)]
            assert not errors, (topic, errors[:3], m)
    events = [m["message"] for m in got.get("/events", [])]
    assert any("loop ready" in e for e in events), events
    assert stats is not None and stats["foxglove"]["published_frames"] > 0
    assert stats["foxglove"]["error"] is None


def test_a_client_joining_mid_sortie_gets_the_calibration_and_the_gains():
    """They are sent once a sortie; the onboard publisher sends them again to a client that
    subscribes later (an engineer opening Foxglove on a running sortie)."""
    import numpy as np

    from onboard.runtime.foxglove import FoxglovePublisher

    frames = FrameList()
    Simulation(load_scenario("static-ahead-20m"), keep_records=False, observers=[frames]).run()
    live = live_mod.FoxgloveLive(port=0)
    pub = FoxglovePublisher(live)
    pub.start()
    try:
        info = frames.info
        pub.new_sortie(info.t0_s, info.law, info.camera_model, info.gains, info.control_rate_hz)

        def offer(part) -> None:
            for f in part:
                pub.offer(
                    f.time_s, np.array(f.vehicle_p_enu_m), np.array(f.vehicle_v_enu_m_s),
                    np.array(f.vehicle_q_wxyz), f.telemetry, f.detection, None, f.gains, 0,
                )  # fmt: skip

        offer(frames.frames[:50])
        end = time.monotonic() + 10
        while pub.published_frames < 50 and time.monotonic() < end:
            time.sleep(0.01)
        assert pub.published_frames == 50 and pub.dropped == 0

        async def join() -> dict[str, dict]:
            async with websockets.connect(live.url(), subprotocols=SUBPROTOCOLS) as ws:
                adv: dict[str, dict] = {}
                while len(adv) < len(CHANNELS):
                    msg = json.loads(await asyncio.wait_for(ws.recv(), 10))
                    if msg["op"] == "advertise":
                        adv.update({c["topic"]: c for c in msg["channels"]})
                topics = ["/camera/calibration", "/gains"]
                subs = [{"id": k, "channelId": adv[t]["id"]} for k, t in enumerate(topics)]
                await ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
                await asyncio.sleep(0.2)  # the server takes the subscription
                offer(frames.frames[50:60])  # the sortie goes on
                got: dict[str, dict] = {}
                while len(got) < 2:
                    data = await asyncio.wait_for(ws.recv(), 10)
                    if isinstance(data, bytes) and data[0] == MESSAGE_DATA:
                        got[topics[struct.unpack_from("<I", data, 1)[0]]] = json.loads(data[13:])
                return got

        got = asyncio.run(join())
    finally:
        pub.stop()
        pub.join(5)
        live.stop()
    assert got["/gains"] == info.gains.to_dict()
    cam = info.camera_model
    assert got["/camera/calibration"]["K"][0] == pytest.approx(cam.f_px)
    assert pub.error is None


def test_onboard_run_foxglove_options_are_checked(capsys):
    from onboard.cli import main

    for argv, needle in (
        (["--foxglove", "127.0.0.1:99999"], "argument --foxglove: '127.0.0.1:99999'"),
        (["--foxglove", ":8765"], "argument --foxglove: ':8765': no host"),
    ):
        with pytest.raises(SystemExit) as exc:
            main(["run", "--camera", "sitl://127.0.0.1:9", *argv])
        err = capsys.readouterr().err
        assert exc.value.code == 2 and needle in err, (argv, err)
    live = live_mod.FoxgloveLive(port=0)
    port = live.port
    try:  # a port in use: one clear line, exit 2
        code = main(
            ["run", "--camera", "sitl://127.0.0.1:9", "--gcs", "", "--mavlink",
             "udpout:127.0.0.1:9", "--foxglove", str(port)]
        )  # fmt: skip
    finally:
        live.stop()
    err = capsys.readouterr().err
    assert code == 2 and f"--foxglove: cannot listen on 127.0.0.1:{port}" in err, err
