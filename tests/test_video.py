"""Live video: H.264 encoder -> RTP/UDP -> depacketiser -> decoder on synthetic frames (every
frame arrives, in order, looking like what was sent; the latency figure is printed), frames
dropped and never queued when the receiver stalls or the sender is slower than the camera,
RTP fragmentation, and the command-line options."""

from __future__ import annotations

import socket
import statistics
import time

import numpy as np
import pytest

pytest.importorskip("av")

from groundstation.app.video import VideoReceiver
from onboard.link.rtp import MAX_PAYLOAD, RtpDepacketizer, RtpPacketizer, rtp_ts_of, split_annexb
from onboard.runtime.video import (
    H264RtpSender,
    Overlay,
    VideoConfig,
    VideoStreamer,
    draw_overlay,
    overlay_of,
)

W, H = 320, 240


def _frame(k: int, noise: np.random.Generator | None = None) -> np.ndarray:
    """A moving red square on a grey gradient (or on noise: large frames)."""
    img = np.empty((H, W, 3), np.uint8)
    img[:] = np.linspace(40, 200, W, dtype=np.uint8)[None, :, None]
    if noise is not None:
        img[:] = noise.integers(0, 255, (H, W, 3), dtype=np.uint8)
    x = (5 * k) % (W - 40)
    img[100:140, x : x + 40] = (30, 30, 220)
    return img


def _wait(cond, timeout_s: float = 10.0) -> bool:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(0.005)
    return cond()


@pytest.fixture
def receiver():
    rx = VideoReceiver("127.0.0.1", 0)
    rx.start()
    yield rx
    rx.stop()
    rx.join(timeout=2)


def test_round_trip_every_frame_in_order_and_alike(receiver):
    sender = H264RtpSender(VideoConfig(port=receiver.port, fps=30))
    n = 60
    sent_ts = []
    try:
        for k in range(n):
            t = time.time()
            sent_ts.append(rtp_ts_of(t))
            assert sender.send(_frame(k), t)
            time.sleep(0.002)  # a camera's pace, roughly: the loopback socket keeps up
        assert _wait(lambda: receiver.frames >= n)
    finally:
        sender.close()
    assert receiver.frames == n and receiver.depack.lost == 0 and receiver.decode_errors == 0
    _count, image, ts = receiver.latest()
    assert ts == sent_ts[-1]
    diff = np.abs(image.astype(int) - _frame(n - 1).astype(int)).mean()
    assert image.shape == (H, W, 3) and diff < 6.0  # H.264 at 2 Mbit/s: close to the source
    lat = sorted(receiver.latencies_s)
    print(
        f"\nencode -> RTP -> decode, {W}x{H}: median {1000 * statistics.median(lat):.1f} ms, "
        f"max {1000 * lat[-1]:.1f} ms over {len(lat)} frames"
    )
    assert receiver.take_jpeg_b64() is not None and receiver.take_jpeg_b64() is None


def test_a_stalled_receiver_drops_old_frames_and_shows_the_newest(receiver):
    """While the receiver stalls, the sender never waits and the kernel's small buffer
    overflows: the backlog is lost, not queued; after it, the next keyframe resynchronises
    and the newest frame is the one shown."""
    rng = np.random.default_rng(3)
    sender = H264RtpSender(VideoConfig(port=receiver.port, fps=30, kbps=8000))
    try:
        sender.send(_frame(0, rng), time.time())
        assert _wait(lambda: receiver.frames == 1)
        receiver.paused.set()
        time.sleep(0.05)
        stalled = 90
        for k in range(1, 1 + stalled):  # three seconds of large frames at once
            assert sender.send(_frame(k, rng), time.time())
        receiver.paused.clear()
        last_ts = None
        for k in range(1 + stalled, 1 + stalled + 45):  # > one GOP: a keyframe comes
            t = time.time()
            last_ts = rtp_ts_of(t)
            sender.send(_frame(k, rng), t)
            time.sleep(0.003)
        assert _wait(lambda: receiver.latest()[2] == last_ts)
    finally:
        sender.close()
    total = 1 + stalled + 45
    assert sender.dropped_link == 0 and sender.frames_sent == total  # the sender never blocked
    assert receiver.depack.lost > 0  # the backlog overflowed: dropped
    assert receiver.frames < total - 30  # at least a second of old video never shown
    print(
        f"\nstall: {total} sent, {receiver.frames} decoded, {receiver.depack.lost} packets dropped"
    )


class _Wedged:
    """A socket whose buffer is full (a slow link) for the first ``full`` sends."""

    def __init__(self, full: int) -> None:
        self.full = full
        self.sent: list[bytes] = []

    def setblocking(self, _flag: bool) -> None:
        pass

    def sendto(self, data: bytes, _addr) -> int:
        if self.full > 0:
            self.full -= 1
            raise BlockingIOError
        self.sent.append(data)
        return len(data)

    def close(self) -> None:
        pass


def test_a_slow_link_drops_the_frame_and_the_next_is_a_keyframe():
    sock = _Wedged(full=1)
    sender = H264RtpSender(VideoConfig(port=5600), sock=sock)
    assert not sender.send(_frame(0), time.time())  # could not be sent: dropped
    assert sender.send(_frame(1), time.time()) and sender.send(_frame(2), time.time())
    assert sender.dropped_link == 1 and sender.frames_sent == 2
    depack = RtpDepacketizer()
    units = [u for u in (depack.push(p) for p in sock.sent) if u is not None]
    assert [u.keyframe for u in units] == [True, False]  # the receiver resynchronises at once


def test_the_streamer_takes_the_newest_frame_and_skips_the_rest():
    """A camera faster than the stream: frames in between are skipped (counted), never
    queued; every frame sent is the newest at its time."""
    rx_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx_sock.bind(("127.0.0.1", 0))
    state = {"seq": 0}

    def latest():
        state["seq"] += 1  # a new frame at every look: far faster than 10 frames/s
        return state["seq"], time.time(), _frame(state["seq"])

    cfg = VideoConfig(port=rx_sock.getsockname()[1], fps=10)
    streamer = VideoStreamer(cfg, latest, lambda: Overlay((10, 10, 20, 20), (50.0, 60.0)))
    streamer.start()
    try:
        assert _wait(lambda: streamer.sender.frames_sent >= 5)
    finally:
        streamer.stop()
        streamer.join(timeout=2)
        rx_sock.close()
    looked = state["seq"]
    sent = streamer.sender.frames_sent
    assert sent >= 5 and streamer.dropped_skipped > 0
    assert sent + streamer.dropped_skipped <= looked  # nothing sent twice, nothing queued


def test_fu_a_fragments_reassemble_and_a_gap_waits_for_a_keyframe():
    sps = bytes([0x67, 1, 2, 3])
    idr = bytes([0x65]) + bytes(range(256)) * 20  # > MAX_PAYLOAD: fragmented
    p_slice = bytes([0x41]) + b"\x07" * 3000
    pk = RtpPacketizer(ssrc=1, seq=65530)  # wraps around
    au1 = b"\x00\x00\x00\x01" + sps + b"\x00\x00\x01" + idr
    pkts1 = pk.packets(au1, 1000)
    assert len(pkts1) == 1 + -(-(len(idr) - 1) // MAX_PAYLOAD)
    d = RtpDepacketizer()
    out = [d.push(p) for p in pkts1]
    assert out[:-1] == [None] * (len(pkts1) - 1)
    assert split_annexb(out[-1].data) == [sps, idr] and out[-1].keyframe
    pkts2 = pk.packets(b"\x00\x00\x00\x01" + p_slice, 4000)
    assert [d.push(p) for p in pkts2[:-1]] == [None] * (len(pkts2) - 1)
    assert split_annexb(d.push(pkts2[-1]).data) == [p_slice]
    pkts3 = pk.packets(b"\x00\x00\x00\x01" + p_slice, 7000)
    for p in pkts3[1:]:  # the first fragment is lost
        assert d.push(p) is None
    assert d.lost == 1
    assert all(d.push(p) is None for p in pk.packets(b"\x00\x00\x00\x01" + p_slice, 10000))
    last = [d.push(p) for p in pk.packets(au1, 13000)][-1]  # a keyframe: shown again
    assert last is not None and last.keyframe


def test_overlay_draws_on_a_copy():
    img = _frame(0)
    out = draw_overlay(img, Overlay((20, 20, 30, 30), (160.0, 120.0)))
    assert not np.shares_memory(out, img) and (out != img).any()
    assert (draw_overlay(img, Overlay()) != img).any()  # the centre cross only
    assert (out[20, 20:50] == (28, 158, 255)).all()  # the detection box's top edge


@pytest.mark.parametrize(
    ("kw", "needle"),
    [
        ({"port": 0}, "port 0 is not in 1..65535"),
        ({"fps": 0.1}, "0.1 frames/s"),
        ({"kbps": 10}, "10 kbit/s"),
        ({"host": ""}, "host is empty"),
    ],
)
def test_video_config_refuses_bad_values(kw, needle):
    with pytest.raises(ValueError, match=needle):
        VideoConfig(**kw)


def test_onboard_run_video_options_are_checked(capsys):
    from onboard.cli import main

    for argv, needle in (
        (["--video", "host:0"], "argument --video: 'host:0': the port must be"),
        (["--video", ":5600"], "argument --video: ':5600': no host"),
        (["--video", "--video-fps", "0"], "argument --video-fps: must be a number of frames/s"),
        (["--video", "--video-fps", "500"], "argument --video-fps: must be a number of frames/s"),
        (["--video", "--video-kbps", "nan"], "argument --video-kbps: must be"),
        (["--video", "--video-kbps", "50"], "video: 50 kbit/s is not in 100..50000"),
        (["--video-overlay", "maybe"], "argument --video-overlay: invalid choice"),
    ):
        try:
            code = main(["run", "--camera", "0", "--mavlink", "udpin:127.0.0.1:0", *argv])
        except SystemExit as exc:
            code = exc.code
        err = capsys.readouterr().err
        assert code == 2 and needle in err, (argv, err)


def test_live_mode_shows_each_new_video_frame_once_in_the_image_panel(receiver):
    """serve --mavlink --video: the published snapshots carry each newly decoded frame (the
    image panel's JPEG) once; none before the first frame."""
    import base64

    import cv2

    from groundstation.app.live import LiveSession

    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    snaps: list[dict] = []
    session = LiveSession(f"udpin:127.0.0.1:{port}", on_snapshot=snaps.append)
    session.video = receiver
    sender = H264RtpSender(VideoConfig(port=receiver.port))

    def shown() -> list[str]:
        return [x["frame_jpeg_b64"] for x in list(snaps) if "frame_jpeg_b64" in x]

    try:
        assert _wait(lambda: len(snaps) >= 3)
        assert shown() == []
        sender.send(_frame(7), time.time())
        assert _wait(lambda: len(shown()) == 1)
        n = len(snaps)
        assert _wait(lambda: len(snaps) >= n + 3)  # more snapshots, no new frame
    finally:
        sender.close()
        session.close()
    assert len(shown()) == 1
    image = cv2.imdecode(np.frombuffer(base64.b64decode(shown()[0]), np.uint8), cv2.IMREAD_COLOR)
    assert image.shape == (H, W, 3)
    assert np.abs(image.astype(int) - _frame(7).astype(int)).mean() < 8.0


def test_onboard_runtime_streams_its_camera_with_a_switchable_overlay(tmp_path, receiver):
    """onboard run --video: the runtime's newest camera frame, with the detection box drawn
    (overlay on) or bare (off), reaches the receiver."""
    from onboard.link.px4 import MavLink
    from onboard.runtime.camera import Frame as CameraFrame
    from onboard.runtime.runner import OnboardRuntime, RuntimeConfig

    def port() -> int:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.bind(("127.0.0.1", 0))
            return s.getsockname()[1]

    fc_port = port()
    fc = MavLink(f"udpin:127.0.0.1:{fc_port}", 1, 1)
    rt = OnboardRuntime(
        RuntimeConfig(
            fc_url=f"udpout:127.0.0.1:{fc_port}",
            camera="sitl://127.0.0.1:9",
            params_path=tmp_path / "params.toml",
            video=VideoConfig(port=receiver.port),
        ),
        log=lambda _line: None,
    )
    box = (100, 60, 60, 60)  # on the plain gradient, clear of the red square
    rt.video_overlay = Overlay(box, (130.0, 90.0))
    top_edge = (slice(59, 62), slice(110, 150))
    try:
        rt.video.start()
        now = rt.clock.now()
        rt.camera.last_frame = CameraFrame(1, now, now, _frame(40))
        assert _wait(lambda: receiver.frames >= 1)
        with_box = receiver.latest()[1][top_edge].reshape(-1, 3).mean(axis=0)
        assert np.abs(with_box - (28, 158, 255)).max() < 40  # the orange detection box
        rt.video.overlay_on = False
        now = rt.clock.now()
        rt.camera.last_frame = CameraFrame(2, now, now, _frame(40))
        assert _wait(lambda: receiver.frames >= 2)
        bare = receiver.latest()[1][top_edge].reshape(-1, 3).mean(axis=0)
        assert np.abs(bare - _frame(40)[top_edge].reshape(-1, 3).mean(axis=0)).max() < 12
    finally:
        rt.video.stop()
        rt.video.join(timeout=2)
        rt.fc.link.close()
        fc.close()
    lat = list(receiver.latencies_s)
    assert len(lat) == 2 and all(0 <= x < 5 for x in lat)  # capture time carried across


def test_overlay_of_the_loop_state():
    from onboard.camera_model import CameraModel
    from onboard.datatypes import Detection

    cam = CameraModel(320, 240, 90.0, 0.0, 0.0)
    det = Detection(10.0, (50.0, 60.0), (40.0, 50.0, 20.0, 20.0), 400.0)
    ov = overlay_of(det, (5.0, -3.0), cam, now_s=10.2)
    assert ov.det_bbox_px == (40.0, 50.0, 20.0, 20.0)
    assert ov.est_center_px == (cam.cu_px + 5.0, cam.cv_px - 3.0)
    assert overlay_of(det, None, cam, now_s=10.6) == Overlay()  # stale detection, no estimate
