"""The telemetry fan-out: what reaches a subscriber's queue, and when."""

import asyncio
from types import SimpleNamespace

from groundstation.app import telemetry_hub
from groundstation.app.telemetry_hub import TelemetryHub


def _fan_out(hub: TelemetryHub, snapshots, clock, monkeypatch) -> list[tuple[bool, str]]:
    """Publish ``snapshots`` at the monotonic times ``clock`` to one subscriber that wants
    camera frames; the messages its queue received, in order."""
    loop = asyncio.new_event_loop()
    try:
        hub.loop = loop
        q: asyncio.Queue = asyncio.Queue(maxsize=100)
        hub.queues[q] = True
        times = iter(clock)
        monkeypatch.setattr(telemetry_hub, "time", SimpleNamespace(monotonic=lambda: next(times)))
        for s in snapshots:
            hub.publish_from_thread(s)
        loop.run_until_complete(asyncio.sleep(0))  # run the broadcasts handed to the loop
        return [q.get_nowait() for _ in range(q.qsize())]
    finally:
        loop.close()


def test_an_unchanged_snapshot_is_repeated_at_the_repeat_period_and_a_change_at_once(
    monkeypatch,
):
    hub = TelemetryHub(repeat_period_s=0.2)
    idle = {"type": "telemetry", "status": {"state": "idle"}}
    running = {"type": "telemetry", "status": {"state": "running"}, "t": 0.1}
    # 40 Hz: idle at 0, 0.025 ... 0.2 (repeated once, at 0.2 s), then a change at 0.225 s
    clock = [0.025 * k for k in range(11)]
    got = _fan_out(hub, [idle] * 10 + [running], clock, monkeypatch)
    texts = [text for _, text in got]
    assert len(texts) == 3
    assert '"idle"' in texts[0] and texts[1] == texts[0] and '"running"' in texts[2]
    assert hub.published == 11 and hub.repeats_held == 8
    assert hub.last == texts[2]  # a new subscriber is sent the newest at once


def test_a_camera_frame_is_always_sent_even_when_the_rest_is_unchanged(monkeypatch):
    hub = TelemetryHub(repeat_period_s=10.0)
    snap = {"type": "telemetry", "t": 1.0}
    with_frame = dict(snap, frame_jpeg_b64="AAAA")
    got = _fan_out(hub, [snap, with_frame, with_frame, snap], [0.0, 0.01, 0.02, 0.03], monkeypatch)
    assert [has_frame for has_frame, _ in got] == [False, True, True]
    assert all("AAAA" in text for _, text in got[1:])
    assert hub.repeats_held == 1
