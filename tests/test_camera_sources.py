"""Camera sources of the onboard runtime: a video file through OpenCV, the SITL stream with
garbage on it, and the camera thread's stamping and reconnecting."""

import math
import socket
import threading
import time

import cv2
import numpy as np
import pytest

from groundstation.sim.render import FrameRenderer
from groundstation.sitl.camera_server import CameraServer
from onboard.camera_model import CameraModel
from onboard.geometry import attitude_from_yaw_pitch_roll
from onboard.perception import RedBalloonDetector
from onboard.runtime.camera import (
    CameraError,
    CameraThread,
    Clock,
    OpenCvSource,
    SitlCameraSource,
    open_source,
)

CAM = CameraModel(320, 240, 90.0)


def _frame(offset_m: float) -> np.ndarray:
    R_WC = attitude_from_yaw_pitch_roll(math.pi / 2) @ CAM.R_BC
    renderer = FrameRenderer(CAM, np.random.default_rng(0))
    return renderer.render(R_WC, np.zeros(3), np.array([offset_m, 10.0, 0.0]), 0.5)


def _wait(pred, timeout_s=5.0):
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if pred():
            return True
        time.sleep(0.01)
    return False


def test_a_video_file_plays_at_its_rate_and_the_balloon_is_found(tmp_path):
    path = tmp_path / "flight.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 20.0, (320, 240))
    assert writer.isOpened()
    for k in range(10):
        writer.write(_frame(-1.0 + 0.2 * k))
    writer.release()
    clock = Clock()
    thread = CameraThread(lambda: OpenCvSource(str(path), clock, latency_s=0.01),
                          RedBalloonDetector(), clock)  # fmt: skip
    thread.start()
    events = []

    def ten_frames():
        events.extend(thread.drain())
        return len(events) >= 10

    assert _wait(ten_frames)
    thread.stop()
    thread.join(3.0)
    events = events[:10]
    assert all(e.detection is not None for e in events)
    us = [e.detection.center_px[0] for e in events]
    assert us == sorted(us)  # the balloon moves right, frame after frame
    caps = [e.capture_time_s for e in events]
    assert all(e.received_time_s - e.capture_time_s == pytest.approx(0.01) for e in events)
    dt = np.diff(caps)
    assert np.median(dt) == pytest.approx(0.05, abs=0.02)  # played at 20 fps, not at once


def test_open_source_errors_are_clear():
    with pytest.raises(CameraError, match="cannot open"):
        OpenCvSource("/nonexistent/video.avi", Clock())
    with pytest.raises(CameraError, match="sitl://HOST:PORT"):
        open_source("sitl://localhost:notaport", Clock())


def test_sitl_stream_stamps_on_the_receivers_clock_and_survives_garbage():
    server = CameraServer("127.0.0.1", 0)
    clock = Clock()
    src = SitlCameraSource(server.url, clock)
    try:
        junk = socket.create_connection(server.address)  # another client sending junk
        junk.sendall(b"\x00\xff" * 10000)
        image = _frame(0.0)
        got: list = []
        t = threading.Thread(target=lambda: got.append(src.read()), daemon=True)
        t.start()
        assert _wait(lambda: server.clients == 2)
        server.publish(image, capture_time_s=123.0, age_s=0.08)
        t.join(3.0)
        frame = got[0]
        assert np.array_equal(frame.image, image)
        assert frame.received_time_s - frame.capture_time_s == pytest.approx(0.08)
        assert abs(frame.received_time_s - clock.now()) < 1.0  # our clock, not the SITL's
        junk.close()
    finally:
        src.close()
        server.close()


def test_a_server_sending_garbage_is_refused_and_the_thread_reconnects():
    listener = socket.socket()
    listener.bind(("127.0.0.1", 0))
    listener.listen(4)
    port = listener.getsockname()[1]

    def bad_server():
        for _ in range(2):
            conn, _ = listener.accept()
            conn.sendall(b"HTTP/1.1 200 OK\r\n" + b"x" * 200)
            time.sleep(0.2)
            conn.close()

    threading.Thread(target=bad_server, daemon=True).start()
    clock = Clock()
    errors: list[str] = []
    thread = CameraThread(
        lambda: SitlCameraSource(f"sitl://127.0.0.1:{port}", clock),
        RedBalloonDetector(),
        clock,
        on_error=errors.append,
        retry_s=0.1,
    )
    thread.start()
    assert _wait(lambda: thread.errors >= 2)
    thread.stop()
    thread.join(3.0)
    listener.close()
    assert thread.frames == 0
    assert any("not a frame header" in e for e in errors)
