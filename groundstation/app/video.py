"""The vehicle's live video on the ground: H.264 over RTP/UDP (``onboard run --video``,
:mod:`onboard.runtime.video`; the wire format is :mod:`onboard.link.rtp`) received,
depacketised and decoded with PyAV in its own thread.

Only the newest decoded frame is kept (the dashboard's image panel takes it as a JPEG with
the next telemetry snapshot): a slow page or a stalled decoder drops frames, never queues
them, and the socket's receive buffer is kept small so a stall cannot leave seconds of old
video waiting. Each frame's glass-to-glass latency is read off its RTP timestamp (the capture
time on the vehicle's wall clock: meaningful on one machine, as in SITL, or with NTP/PTP).
"""

from __future__ import annotations

import base64
import socket
import statistics
import threading
import time
from collections import deque
from collections.abc import Callable

import cv2
import numpy as np

from onboard.link.rtp import AccessUnit, RtpDepacketizer, age_of_rtp_ts

RCVBUF_BYTES = 256 * 1024  # about a second of 2 Mbit/s video at most waits in the kernel


class VideoReceiver(threading.Thread):
    """Receives on UDP ``host:port``; :meth:`take_jpeg_b64` gives each new frame once."""

    def __init__(
        self,
        host: str = "127.0.0.1",
        port: int = 5600,
        wall_clock: Callable[[], float] = time.time,
    ) -> None:
        super().__init__(name="video-rx", daemon=True)
        import av

        self._av = av
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        self.sock = socket.socket(family, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RCVBUF_BYTES)
        self.sock.bind((host, port))  # an OSError (port in use) reaches the caller
        self.sock.settimeout(0.2)
        self.port = self.sock.getsockname()[1]
        self.wall_clock = wall_clock
        self.depack = RtpDepacketizer()
        self.decoder = self._new_decoder()
        self.frames = 0  # decoded
        self.decode_errors = 0
        self.latencies_s: deque[float] = deque(maxlen=2000)
        self._latest: tuple[int, np.ndarray, int] | None = None  # (count, BGR, rtp ts)
        self._taken = 0
        self._lock = threading.Lock()
        self._halt = threading.Event()
        self.paused = threading.Event()  # tests: a stalled receiver

    def _new_decoder(self):
        dec = self._av.CodecContext.create("h264", "r")
        dec.thread_count = 1  # frame threading would hold frames back
        return dec

    def stop(self) -> None:
        self._halt.set()

    def run(self) -> None:
        try:
            while not self._halt.is_set():
                if self.paused.is_set():
                    self._halt.wait(0.01)
                    continue
                try:
                    packet = self.sock.recv(65536)
                except TimeoutError:
                    continue
                except OSError:
                    break
                au = self.depack.push(packet)
                if au is not None:
                    self._decode(au)
        finally:
            self.sock.close()

    def _decode(self, au: AccessUnit) -> None:
        try:
            frames = self.decoder.decode(self._av.Packet(au.data))
        except (self._av.error.FFmpegError, ValueError):
            self.decode_errors += 1
            self.decoder = self._new_decoder()  # start clean at the next keyframe
            self.depack._broken = True
            return
        for f in frames:
            image = f.to_ndarray(format="bgr24")
            self.latencies_s.append(age_of_rtp_ts(au.rtp_ts, self.wall_clock()))
            with self._lock:
                self.frames += 1
                self._latest = (self.frames, image, au.rtp_ts)

    def latest(self) -> tuple[int, np.ndarray, int] | None:
        """(frame count, BGR image, RTP timestamp) of the newest decoded frame."""
        with self._lock:
            return self._latest

    def take_jpeg_b64(self, quality: int = 70) -> str | None:
        """The newest frame as base64 JPEG if it was not taken before, else None."""
        got = self.latest()
        if got is None or got[0] == self._taken:
            return None
        self._taken = got[0]
        ok, jpg = cv2.imencode(".jpg", got[1], [cv2.IMWRITE_JPEG_QUALITY, quality])
        return base64.b64encode(jpg.tobytes()).decode("ascii") if ok else None

    def stats(self) -> dict:
        lat = sorted(self.latencies_s)
        return {
            "frames": self.frames,
            "packets_lost": self.depack.lost,
            "decode_errors": self.decode_errors,
            "latency_median_ms": None if not lat else 1000 * statistics.median(lat),
            "latency_p95_ms": None if not lat else 1000 * lat[int(0.95 * (len(lat) - 1))],
        }
