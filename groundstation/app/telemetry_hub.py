"""The telemetry fan-out: the session's snapshots, handed in from its thread, go to every
websocket subscriber of the dashboard (``/ws/telemetry``), each through a short queue of its own."""

from __future__ import annotations

import asyncio
import json
import time
from typing import Any

# An unchanged snapshot (an idle, paused or finished session publishes the same one at the full
# rate) goes out at most this often: a page redraws every message it receives, and an idle
# dashboard redrawing the same snapshot 40 times a second kept a browser at about half a core.
REPEAT_PERIOD_S = 0.2


class TelemetryHub:
    """Fans telemetry out to websocket subscribers; a slow one loses old frames, not new.

    A subscriber may send ``{"frames": false}`` (a hidden browser tab does) to stop receiving
    camera frames, the bulk of the traffic, and ``{"frames": true}`` to resume. A snapshot
    identical to the last one broadcast, without a camera frame, is broadcast again only
    ``repeat_period_s`` after it (a new subscriber gets the last one at once)."""

    def __init__(self, repeat_period_s: float = REPEAT_PERIOD_S) -> None:
        self.repeat_period_s = repeat_period_s
        self._broadcast_at = -float("inf")  # time.monotonic() of the last broadcast
        self.repeats_held = 0  # unchanged snapshots not broadcast
        self.loop: asyncio.AbstractEventLoop | None = None
        self.queues: dict[asyncio.Queue, bool] = {}  # queue -> wants camera frames
        self.last: str | None = None
        self.sent: dict[int, int] = {}  # messages sent, per connected subscriber
        self.published = 0  # snapshots handed in by the session

    def publish_from_thread(self, snapshot: dict[str, Any]) -> None:
        self.published += 1
        full = json.dumps(snapshot, separators=(",", ":"))
        lean = full
        if "frame_jpeg_b64" in snapshot:
            lean = json.dumps(
                {k: v for k, v in snapshot.items() if k != "frame_jpeg_b64"}, separators=(",", ":")
            )
        now = time.monotonic()
        if full is lean and lean == self.last and now < self._broadcast_at + self.repeat_period_s:
            self.repeats_held += 1
            return
        self.last = lean
        self._broadcast_at = now
        if self.loop is not None and self.queues:
            self.loop.call_soon_threadsafe(self._broadcast, full, lean)

    def _broadcast(self, full: str, lean: str) -> None:
        has_frame = full is not lean
        for q, frames in list(self.queues.items()):
            item = (has_frame and frames, full if frames else lean)
            if q.full():
                # a slow subscriber loses its oldest message without a camera frame: a frame
                # (sent once, after a seek) is not lost to the snapshots that follow it
                held = [q.get_nowait() for _ in range(q.qsize())]
                drop = next((k for k, (f, _) in enumerate(held) if not f), 0)
                del held[drop]
                for h in held:
                    q.put_nowait(h)
            q.put_nowait(item)
