"""The telemetry fan-out: the session's snapshots, handed in from its thread, go to every
websocket subscriber of the dashboard (``/ws/telemetry``), each through a short queue of its own."""

from __future__ import annotations

import asyncio
import json
from typing import Any


class TelemetryHub:
    """Fans telemetry out to websocket subscribers; a slow one loses old frames, not new.

    A subscriber may send ``{"frames": false}`` (a hidden browser tab does) to stop receiving
    camera frames, the bulk of the traffic, and ``{"frames": true}`` to resume."""

    def __init__(self) -> None:
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
        self.last = lean
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
