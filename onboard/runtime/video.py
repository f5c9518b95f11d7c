"""The onboard camera as live video: H.264 (PyAV's libx264, zero-latency tuning, no B-frames)
over RTP/UDP (RFC 6184: single NAL units and FU-A fragments, payload type 96, 90 kHz clock),
port 5600 by default: what QGroundControl's video widget (UDP h.264) and the ground station's
image panel (:mod:`groundstation.app.video`) receive.

Frames are dropped, never queued: :class:`VideoStreamer` takes only the newest camera frame
(frames captured while it encodes are skipped), and a frame the socket cannot take at once
(a slow link) is abandoned and the next one sent as a keyframe, so the receiver recovers at
once instead of falling behind. The video thread runs at a lower scheduling priority than
the control thread (nice +10 on Linux; PyAV releases the interpreter lock while it encodes),
so the loop gets the CPU first. The detection (orange box) and the DKF estimate (green
circle) are drawn on the frame when ``overlay`` is on.

The RTP timestamp is the capture time on the wall clock (90 kHz, modulo 2^32), so a receiver
on a clock-synchronised machine reads the glass-to-glass latency off each frame.
"""

from __future__ import annotations

import contextlib
import os
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from fractions import Fraction

import cv2
import numpy as np

from ..link.rtp import RTP_CLOCK_HZ, RtpPacketizer, rtp_ts_of

DEFAULT_PORT = 5600  # QGroundControl's UDP video port
VIDEO_NICE = 10  # the video thread's priority below the control thread's (Linux)


@dataclass(frozen=True)
class VideoConfig:
    """Where and how the camera is streamed (``onboard run --video``)."""

    host: str = "127.0.0.1"
    port: int = DEFAULT_PORT
    fps: float = 30.0  # at most this many frames a second are encoded
    kbps: int = 2000  # target bit rate
    overlay: bool = True  # detection and DKF estimate drawn on the frames
    max_width_px: int = 1280  # larger frames are scaled down (keeps encoding real-time)

    def __post_init__(self) -> None:
        if not self.host:
            raise ValueError("video: the receiver's host is empty")
        if not 1 <= self.port <= 65535:
            raise ValueError(f"video: port {self.port} is not in 1..65535")
        if not 0.5 <= self.fps <= 120.0:
            raise ValueError(f"video: {self.fps} frames/s is not in 0.5..120")
        if not 100 <= self.kbps <= 50_000:
            raise ValueError(f"video: {self.kbps} kbit/s is not in 100..50000")
        if not 64 <= self.max_width_px <= 4096:
            raise ValueError(f"video: max width {self.max_width_px} px is not in 64..4096")


# ---------------------------------------------------------------------- overlay
@dataclass(frozen=True)
class Overlay:
    """What is drawn on a frame (pixels, u right, v down)."""

    det_bbox_px: tuple[float, float, float, float] | None = None  # x, y, width, height
    est_center_px: tuple[float, float] | None = None  # the DKF's target estimate


DETECTION_SHOWN_S = 0.5  # a detection older than this is not drawn


def overlay_of(detection, e_est_px, camera, now_s: float) -> Overlay:
    """From the loop's latest detection (drawn while under half a second old at ``now_s``,
    onboard clock), its DKF error estimate (pixels from the principal point) and camera
    model."""
    if detection is not None and now_s - detection.capture_time_s > DETECTION_SHOWN_S:
        detection = None
    est = None
    if e_est_px is not None and camera is not None:
        est = (camera.cu_px + float(e_est_px[0]), camera.cv_px + float(e_est_px[1]))
    return Overlay(None if detection is None else tuple(detection.bbox_px), est)


def draw_overlay(image: np.ndarray, ov: Overlay) -> np.ndarray:
    """A copy of ``image`` (BGR) with the detection box and the DKF estimate."""
    out = image.copy()
    h, w = out.shape[:2]
    cv2.drawMarker(out, (w // 2, h // 2), (255, 255, 255), cv2.MARKER_CROSS, 14, 1)
    if ov.det_bbox_px is not None:
        x, y, bw, bh = (round(float(c)) for c in ov.det_bbox_px)
        cv2.rectangle(out, (x, y), (x + bw, y + bh), (28, 158, 255), 2)
    if ov.est_center_px is not None and all(np.isfinite(ov.est_center_px)):
        u, v = (round(float(c)) for c in ov.est_center_px)
        cv2.circle(out, (u, v), 10, (92, 194, 26), 2)
    return out


# ---------------------------------------------------------------------- encoder and sender
class H264RtpSender:
    """Encodes BGR frames and sends them as RTP datagrams without ever blocking: a frame the
    socket cannot take is abandoned (counted in ``dropped_link``) and the next is a keyframe."""

    def __init__(self, config: VideoConfig, sock: socket.socket | None = None) -> None:
        import av  # PyAV: imported only where video is used

        self._av = av
        self.config = config
        self.address = (config.host, config.port)
        if sock is None:
            family = socket.AF_INET6 if ":" in config.host else socket.AF_INET
            sock = socket.socket(family, socket.SOCK_DGRAM)
        sock.setblocking(False)
        self.sock = sock
        self.rtp = RtpPacketizer()
        self.enc = None
        self._size: tuple[int, int] | None = None
        self._force_key = True
        self._pts = 0
        self.frames_sent = 0
        self.dropped_link = 0
        self.bytes_sent = 0

    def _encoder(self, w: int, h: int):
        av = self._av
        enc = av.CodecContext.create("libx264", "w")
        enc.width, enc.height, enc.pix_fmt = w, h, "yuv420p"
        enc.time_base = Fraction(1, RTP_CLOCK_HZ)
        enc.framerate = Fraction(self.config.fps).limit_denominator(1000)
        enc.bit_rate = self.config.kbps * 1000
        enc.gop_size = max(int(self.config.fps), 1)  # a keyframe a second for late joiners
        enc.max_b_frames = 0
        enc.options = {"preset": "ultrafast", "tune": "zerolatency", "repeat-headers": "1"}
        enc.thread_count = 1
        return enc

    def send(self, image_bgr: np.ndarray, capture_wall_s: float) -> bool:
        """Encode and send one frame; False when it was dropped (a slow link)."""
        h, w = image_bgr.shape[:2]
        if w > self.config.max_width_px:
            scale = self.config.max_width_px / w
            image_bgr = cv2.resize(image_bgr, (self.config.max_width_px, round(h * scale)))
            h, w = image_bgr.shape[:2]
        w2, h2 = w - w % 2, h - h % 2  # 4:2:0 needs even sides
        if (w2, h2) != (w, h):
            image_bgr = image_bgr[:h2, :w2]
        if self._size != (w2, h2):
            self.enc, self._size, self._force_key = self._encoder(w2, h2), (w2, h2), True
        ts = rtp_ts_of(capture_wall_s)
        frame = self._av.VideoFrame.from_ndarray(
            np.ascontiguousarray(image_bgr), format="bgr24"
        ).reformat(format="yuv420p")
        self._pts += round(RTP_CLOCK_HZ / self.config.fps)
        frame.pts = self._pts
        if self._force_key:
            frame.pict_type = self._av.video.frame.PictureType.I
        data = b"".join(bytes(p) for p in self.enc.encode(frame))
        if not data:
            return False
        self._force_key = False
        for pkt in self.rtp.packets(data, ts):
            try:
                self.sock.sendto(pkt, self.address)
            except (BlockingIOError, InterruptedError):
                self.dropped_link += 1
                self._force_key = True  # the receiver resynchronises on the next frame
                return False
            except OSError:  # no route, receiver refused (ICMP): the link, not us
                self.dropped_link += 1
                self._force_key = True
                return False
            self.bytes_sent += len(pkt)
        self.frames_sent += 1
        return True

    def close(self) -> None:
        self.sock.close()


class VideoStreamer(threading.Thread):
    """Streams the newest camera frame, at most ``fps`` a second, in its own thread.

    ``latest`` returns the newest frame as ``(seq, capture_wall_s, image_bgr)`` or None;
    ``overlay`` what to draw on it. Frames that arrive while a frame is being encoded and sent
    are skipped (``dropped_skipped``): the stream stays at the camera's present."""

    def __init__(
        self,
        config: VideoConfig,
        latest: Callable[[], tuple[int, float, np.ndarray] | None],
        overlay: Callable[[], Overlay] | None = None,
        sender: H264RtpSender | None = None,
        on_error: Callable[[str], None] | None = None,
    ) -> None:
        super().__init__(name="video", daemon=True)
        self.config = config
        self.latest = latest
        self.overlay = overlay
        self.sender = sender or H264RtpSender(config)
        self.on_error = on_error
        self.dropped_skipped = 0
        self.overlay_on = config.overlay  # switchable while streaming
        self._halt = threading.Event()

    def stop(self) -> None:
        self._halt.set()

    def run(self) -> None:
        with contextlib.suppress(AttributeError, OSError):  # Linux: this thread only
            os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), VIDEO_NICE)
        last_seq: int | None = None
        period = 1.0 / self.config.fps
        next_t = time.monotonic()
        while not self._halt.is_set():
            got = self.latest()
            if got is None or got[0] == last_seq:
                self._halt.wait(0.002)
                continue
            now = time.monotonic()
            if now < next_t:  # faster than the stream's rate: this one is skipped
                self._halt.wait(min(next_t - now, 0.002))
                continue
            seq, capture_wall_s, image = got
            if last_seq is not None and seq > last_seq + 1:
                self.dropped_skipped += seq - last_seq - 1
            last_seq = seq
            next_t = max(next_t + period, now)
            if self.overlay_on and self.overlay is not None:
                image = draw_overlay(image, self.overlay())
            try:
                self.sender.send(image, capture_wall_s)
            except Exception as exc:  # an encoder failure ends the video, never the flight
                if self.on_error is not None:
                    self.on_error(f"video stopped: {type(exc).__name__}: {exc}")
                break
        self.sender.close()

    def stats(self) -> dict:
        s = self.sender
        return {
            "frames_sent": s.frames_sent,
            "dropped_skipped": self.dropped_skipped,
            "dropped_link": s.dropped_link,
            "bytes_sent": s.bytes_sent,
        }


def runtime_streamer(runtime) -> VideoStreamer:
    """The streamer of an :class:`~onboard.runtime.runner.OnboardRuntime`: its camera
    thread's newest frame (capture time moved from the onboard clock to the wall clock) and
    the overlay the runtime keeps in ``video_overlay``."""
    clock = runtime.clock

    def latest():
        f = runtime.camera.last_frame
        if f is None:
            return None
        return f.seq, time.time() - (clock.now() - f.capture_time_s), f.image

    return VideoStreamer(
        runtime.config.video,
        latest,
        lambda: runtime.video_overlay,
        on_error=lambda msg: runtime.events.add("warning", msg),
    )
