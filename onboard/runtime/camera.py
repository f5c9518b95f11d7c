"""Camera sources and the camera thread: each frame is stamped with its capture time on the
onboard clock the moment it arrives, the detector runs on it in the camera's own thread, and
the detections wait in a queue for the control loop.

Sources: anything OpenCV opens (a device index ``0``, a V4L2 path, a GStreamer pipeline with
``!`` in it, a video file, played at its own frame rate) and ``sitl://HOST:PORT``, the SITL
vehicle's camera stream (its wire format: :mod:`onboard.link.sitl_camera`).
"""

from __future__ import annotations

import collections
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np

from ..datatypes import Detection
from ..link.sitl_camera import SITL_HEADER, parse_header
from ..perception.detector import Detector


class CameraError(RuntimeError):
    """A camera source that cannot be opened or sent something that is not a frame."""


@dataclass(frozen=True)
class Frame:
    seq: int
    capture_time_s: float  # onboard clock
    received_time_s: float  # onboard clock
    image: np.ndarray  # BGR, height x width x 3


class Clock:
    """The onboard clock: seconds since the runtime started (monotonic)."""

    def __init__(self) -> None:
        self._t0 = time.monotonic()

    def now(self) -> float:
        return time.monotonic() - self._t0


# ---------------------------------------------------------------------- sources
class SitlCameraSource:
    def __init__(self, url: str, clock: Clock, timeout_s: float = 2.0) -> None:
        host, _, port = url.removeprefix("sitl://").rpartition(":")
        try:
            self.address = (host or "127.0.0.1", int(port))
        except ValueError:
            raise CameraError(f"camera {url!r}: expected sitl://HOST:PORT") from None
        self.clock = clock
        self.timeout_s = timeout_s
        self._sock: socket.socket | None = None
        self.url = url

    def _connect(self) -> socket.socket:
        s = socket.create_connection(self.address, timeout=self.timeout_s)
        s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        return s

    def _recv_exact(self, n: int) -> bytes:
        buf = bytearray(n)
        self._recv_into(memoryview(buf))
        return bytes(buf)

    def _recv_into(self, view: memoryview) -> None:
        """Fill ``view`` (bytes) from the stream."""
        n, got = len(view), 0
        while got < n:
            k = self._sock.recv_into(view[got:], n - got)
            if k == 0:
                raise CameraError("SITL camera stream closed")
            got += k

    def read(self) -> Frame:
        if self._sock is None:
            try:
                self._sock = self._connect()
            except OSError as exc:
                raise CameraError(f"cannot connect to {self.url}: {exc}") from None
        try:
            header = self._recv_exact(SITL_HEADER.size)
            received = self.clock.now()
            try:
                seq, w, h, age_s = parse_header(header)
            except ValueError as exc:
                raise CameraError(str(exc)) from None
            # straight into the frame's own array: no copy of ~1 MB per frame
            image = np.empty((h, w, 3), np.uint8)
            self._recv_into(memoryview(image).cast("B"))
        except (OSError, CameraError) as exc:
            self.close()
            raise CameraError(str(exc)) from None
        return Frame(seq, received - age_s, received, image)

    def close(self) -> None:
        if self._sock is not None:
            try:
                self._sock.close()
            finally:
                self._sock = None


class OpenCvSource:
    """A device, V4L2 path, GStreamer pipeline or video file; capture time = grab time minus
    the configured exposure-to-grab latency."""

    def __init__(self, spec: str, clock: Clock, latency_s: float = 0.0) -> None:
        self.clock = clock
        self.latency_s = latency_s
        self.spec = spec
        if spec.isdigit():
            self.cap = cv2.VideoCapture(int(spec))
        elif "!" in spec:
            self.cap = cv2.VideoCapture(spec, cv2.CAP_GSTREAMER)
        else:
            self.cap = cv2.VideoCapture(spec)
        if not self.cap.isOpened():
            raise CameraError(f"OpenCV cannot open camera {spec!r}")
        fps = self.cap.get(cv2.CAP_PROP_FPS)
        frames = self.cap.get(cv2.CAP_PROP_FRAME_COUNT)
        self._file_period_s = (1.0 / fps) if (frames and frames > 0 and fps and fps > 0) else 0.0
        self._next = time.monotonic()
        self._seq = 0

    def read(self) -> Frame:
        if self._file_period_s:  # a video file plays at its own rate, like a live camera
            delay = self._next - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            self._next = max(self._next + self._file_period_s, time.monotonic() - 1.0)
        ok, image = self.cap.read()
        t = self.clock.now()
        if not ok or image is None:
            raise CameraError(f"camera {self.spec!r}: no more frames")
        if image.ndim == 2:
            image = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
        self._seq += 1
        return Frame(self._seq, t - self.latency_s, t, image)

    def close(self) -> None:
        self.cap.release()


def open_source(spec: str, clock: Clock, latency_s: float = 0.0):
    if spec.startswith("sitl://"):
        return SitlCameraSource(spec, clock)
    return OpenCvSource(spec, clock, latency_s)


# ---------------------------------------------------------------------- the thread
@dataclass(frozen=True)
class DetectionEvent:
    detection: Detection | None
    frame_seq: int
    capture_time_s: float
    received_time_s: float
    detected_time_s: float
    image_size: tuple[int, int]


class CameraThread(threading.Thread):
    """Reads frames, runs the detector, hands each result to ``on_detection`` (if given) and
    queues it; reconnects after a failure."""

    def __init__(
        self,
        source_factory: Callable[[], object],
        detector: Detector,
        clock: Clock,
        on_error: Callable[[str], None] | None = None,
        retry_s: float = 1.0,
        on_detection: Callable[[DetectionEvent], None] | None = None,
    ) -> None:
        super().__init__(name="camera", daemon=True)
        self.source_factory = source_factory
        self.detector = detector
        self.clock = clock
        self.on_error = on_error
        self.retry_s = retry_s
        self.on_detection = on_detection  # called here, on the camera thread, per event
        self.events: collections.deque[DetectionEvent] = collections.deque(maxlen=64)
        self.frames = 0
        self.detections = 0
        self.errors = 0
        self.last_frame: Frame | None = None
        self._halt = threading.Event()

    def stop(self) -> None:
        self._halt.set()

    def run(self) -> None:
        source = None
        last_error = ""
        while not self._halt.is_set():
            try:
                if source is None:
                    source = self.source_factory()
                frame = source.read()
            except CameraError as exc:
                self.errors += 1
                if str(exc) != last_error and self.on_error is not None:
                    self.on_error(str(exc))
                last_error = str(exc)
                if source is not None:
                    source.close()
                    source = None
                self._halt.wait(self.retry_s)
                continue
            last_error = ""
            self.frames += 1
            self.last_frame = frame
            det = self.detector.detect(frame.image, frame.capture_time_s)
            if det is not None:
                self.detections += 1
            h, w = frame.image.shape[:2]
            ev = DetectionEvent(
                det,
                frame.seq,
                frame.capture_time_s,
                frame.received_time_s,
                self.clock.now(),
                (w, h),
            )
            self.events.append(ev)  # queued first: the tick after on_detection finds it
            if self.on_detection is not None:
                try:
                    self.on_detection(ev)
                except Exception as exc:  # the camera thread must keep running
                    self.errors += 1
                    if self.on_error is not None:
                        self.on_error(f"on_detection failed: {type(exc).__name__}: {exc}")
        if source is not None:
            source.close()

    def drain(self) -> list[DetectionEvent]:
        out = []
        while True:
            try:
                out.append(self.events.popleft())
            except IndexError:
                return out
