"""The MAVLink adapter: frame conversions, robustness to garbage, signing, the tlog."""

import math
import os
import socket
import struct
import time
from types import SimpleNamespace

import numpy as np
import pytest
from pymavlink import mavutil

from onboard.geometry import attitude_from_yaw_pitch_roll, quat_to_rotmat, rotmat_to_quat
from onboard.link.frame_encoder import FrameEncoder
from onboard.link.px4 import (
    CMD_START,
    MODE_HOLD,
    MODE_OFFBOARD,
    LinkError,
    MavLink,
    enu_to_ned,
    flu_to_frd,
    frd_to_flu,
    load_signing_key,
    mavlink,
    ned_to_enu,
    px4_mode_name,
    quat_enu_flu_to_ned_frd,
    quat_ned_frd_to_enu_flu,
)
from onboard.link.tlog import TlogWriter

from .sitl_rig import free_port


def _poll_until(link: MavLink, kind: str, timeout_s: float = 2.0):
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        for m in link.poll():
            if m.get_type() == kind:
                return m
        time.sleep(0.005)
    return None


# ---------------------------------------------------------------------- frames
def test_vector_conversions_round_trip_and_axes():
    rng = np.random.default_rng(1)
    for _ in range(100):
        v = rng.normal(size=3)
        assert np.allclose(enu_to_ned(ned_to_enu(v)), v)
        assert np.allclose(flu_to_frd(frd_to_flu(v)), v)
    assert np.allclose(ned_to_enu([1.0, 0.0, 0.0]), [0.0, 1.0, 0.0])  # north
    assert np.allclose(ned_to_enu([0.0, 0.0, 1.0]), [0.0, 0.0, -1.0])  # down
    assert np.allclose(frd_to_flu([0.0, 1.0, 0.0]), [0.0, -1.0, 0.0])  # right


def test_quaternion_round_trip_and_meaning():
    rng = np.random.default_rng(2)
    for _ in range(200):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        back = quat_ned_frd_to_enu_flu(quat_enu_flu_to_ned_frd(q))
        assert min(np.linalg.norm(back - q), np.linalg.norm(back + q)) < 1e-9
    # facing north, level: ENU yaw 90 deg is PX4 yaw 0 (identity in NED/FRD)
    q_enu = rotmat_to_quat(attitude_from_yaw_pitch_roll(math.pi / 2))
    assert np.allclose(quat_enu_flu_to_ned_frd(q_enu), [1.0, 0.0, 0.0, 0.0], atol=1e-12)
    # facing east, nose 10 deg up: PX4 sees yaw 90 deg, pitch +10 deg
    R = attitude_from_yaw_pitch_roll(0.0, math.radians(10.0))
    R_ned = quat_to_rotmat(quat_enu_flu_to_ned_frd(rotmat_to_quat(R)))
    fwd_ned = R_ned @ np.array([1.0, 0.0, 0.0])
    assert np.allclose(fwd_ned, [0.0, math.cos(math.radians(10)), -math.sin(math.radians(10))])


def test_px4_mode_names():
    assert px4_mode_name(MODE_OFFBOARD) == "OFFBOARD"
    assert px4_mode_name(MODE_HOLD) == "HOLD"


# ---------------------------------------------------------------------- links
def test_bad_url_and_bad_key_are_clear_errors(tmp_path):
    with pytest.raises(LinkError, match="cannot open MAVLink link"):
        MavLink("udpin:127.0.0.1:notaport", 1, 191)
    key = tmp_path / "key"
    key.write_text("abc")
    with pytest.raises(LinkError, match="64 hex digits"):
        load_signing_key(str(key))
    with pytest.raises(LinkError, match="cannot read"):
        load_signing_key(str(tmp_path / "missing"))


def _garbage_frames() -> list[bytes]:
    """Random bytes and broken MAVLink frames (well-formed frames with nonsense inside are
    the application's business: see test_sitl.py)."""
    rng = np.random.default_rng(3)
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    good = mav.command_long_encode(1, 191, CMD_START, 0, 0, 0, 0, 0, 0, 0, 0).pack(mav)
    bad_crc = bytearray(good)
    bad_crc[-1] ^= 0xFF
    frames = [rng.bytes(int(n)) for n in rng.integers(1, 300, 30)]
    frames += [bytes(bad_crc), good[: len(good) // 2], b"\xfd" * 40, b"\xfe\xff" * 100]
    frames += [b"\xfd\x09\x00\x00\x00\x01\x01\xff\xff\xff" + rng.bytes(20)]  # unknown msg id
    return frames


def test_garbage_is_counted_dropped_and_the_sender_not_answered():
    port = free_port()
    link = MavLink(f"udpin:127.0.0.1:{port}", 1, 191)
    peer = MavLink(f"udpout:127.0.0.1:{port}", 255, 190)
    junk = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    junk.bind(("127.0.0.1", 0))
    junk.settimeout(0.3)
    try:
        for f in _garbage_frames():
            junk.sendto(f, ("127.0.0.1", port))
        peer.heartbeat(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        got = []
        end = time.monotonic() + 2.0
        while time.monotonic() < end and not any(m.get_type() == "HEARTBEAT" for m in got):
            got += link.poll()
            time.sleep(0.005)
        kinds = [m.get_type() for m in got]
        assert "HEARTBEAT" in kinds  # the valid frame still gets through
        assert link.bad_frames >= 10
        assert link.refused_peers >= 1
        link.heartbeat(mavlink.MAV_TYPE_ONBOARD_CONTROLLER, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        assert _poll_until(peer, "HEARTBEAT") is not None  # the real peer is answered
        with pytest.raises(TimeoutError):
            junk.recvfrom(1024)  # the garbage sender is not
    finally:
        junk.close()
        link.close()
        peer.close()


def test_signed_link_refuses_unsigned_commands_and_accepts_signed_ones():
    key = os.urandom(32)
    port = free_port()
    onboard = MavLink(
        f"udpin:127.0.0.1:{port}", 1, 191, key, unsigned_ok=(mavlink.MAVLINK_MSG_ID_HEARTBEAT,)
    )
    unsigned = MavLink(f"udpout:127.0.0.1:{port}", 255, 190)
    signed = MavLink(f"udpout:127.0.0.1:{port}", 255, 190, key, unsigned_ok=None)
    wrong = MavLink(f"udpout:127.0.0.1:{port}", 255, 190, os.urandom(32), unsigned_ok=None)
    try:
        for link in (unsigned, wrong):
            link.send(link.mav.command_long_encode(1, 191, CMD_START, 0, 0, 0, 0, 0, 0, 0, 0))
        unsigned.heartbeat(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        assert _poll_until(onboard, "COMMAND_LONG", 0.5) is None
        assert onboard.bad_frames >= 2
        signed.send(signed.mav.command_long_encode(1, 191, CMD_START, 0, 0, 0, 0, 0, 0, 0, 0))
        msg = _poll_until(onboard, "COMMAND_LONG")
        assert msg is not None and msg.command == CMD_START
    finally:
        for link in (onboard, unsigned, signed, wrong):
            link.close()


class _Capture:
    def __init__(self) -> None:
        self.frames: list[bytes] = []

    def write(self, frame) -> None:
        self.frames.append(bytes(frame))


def test_frame_encoder_puts_pymavlink_s_bytes_on_the_wire():
    """SET_ATTITUDE_TARGET packed directly (the control tick's send) is pymavlink's frame,
    byte for byte: zeros, negative zero, NaN, limits, trimmed trailing zeros, the sequence
    number wrapping; and a signed link falls back to pymavlink's signing."""
    enc = FrameEncoder(mavlink.MAVLink_set_attitude_target_message)
    rng = np.random.default_rng(5)
    ref = mavlink.MAVLink(_Capture(), 1, 191)
    link = MavLink(f"udpout:127.0.0.1:{free_port()}", 1, 191)
    try:
        link.mav.file = _Capture()  # pymavlink's write (another kind of link)
        # and the GIL-held datagram's (a UDP link's: datagram.py), into the same list
        link._datagrams = SimpleNamespace(send=lambda frame, _to: link.mav.file.write(frame) or 1)
        specials = [0.0, -0.0, math.nan, math.inf, 1e-40, 20.0]
        for k in range(600):
            t_ms = int(rng.choice([0, 1, 0xFFFFFFFF, int(rng.integers(0, 2**32))]))
            rates = [float(rng.choice(specials)) if rng.random() < 0.3 else float(rng.normal())
                     for _ in range(3)]  # fmt: skip
            thrust = 0.0 if k % 7 == 0 else float(rng.random())
            ids = [int(rng.integers(0, 2)), int(rng.integers(0, 2)), int(rng.choice([0, 7, 128]))]
            q = (1.0, 0.0, 0.0, 0.0)
            assert link.send_fields(enc, t_ms, *q, *rates, thrust, *ids)
            ref.send(ref.set_attitude_target_encode(t_ms, *ids, q, *rates, thrust))
        assert link.mav.file.frames == ref.file.frames
        assert link.sent == 600 and link.mav.seq == ref.seq == 600 % 256
    finally:
        link.close()
    key = os.urandom(32)
    signed = MavLink(f"udpout:127.0.0.1:{free_port()}", 1, 191, key)
    try:
        signed.mav.file = _Capture()
        assert signed.send_fields(enc, 5, 1.0, 0.0, 0.0, 0.0, 0.1, 0.2, 0.3, 0.5, 1, 1, 7)
        frame = signed.mav.file.frames[0]
        assert frame[2] & mavlink.MAVLINK_IFLAG_SIGNED and len(frame) == 12 + 39 + 13
        msg = mavlink.MAVLink(None, 255, 190).decode(bytearray(frame))
        assert (msg.time_boot_ms, msg.type_mask) == (5, 7)
        assert abs(msg.body_yaw_rate - 0.3) < 1e-6 and abs(msg.thrust - 0.5) < 1e-6
    finally:
        signed.close()


def test_tlog_is_readable_by_pymavlink_and_never_overwritten(tmp_path):
    path = tmp_path / "run.tlog"
    tlog = TlogWriter(path)
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=191)
    for i in range(5):
        tlog.write(mav.statustext_encode(6, f"event {i}".encode()).pack(mav))
    tlog.close()
    log = mavutil.mavlink_connection(str(path))
    texts = []
    while (m := log.recv_match(type="STATUSTEXT")) is not None:
        texts.append(m.text)
    assert texts == [f"event {i}" for i in range(5)]
    with pytest.raises(FileExistsError):
        TlogWriter(path)
    assert struct.unpack(">Q", path.read_bytes()[:8])[0] > 1.6e15  # UNIX microseconds


def test_real32_parameter_values_read_back_as_their_decimals():
    from onboard.link.px4 import real32

    for v in (0.05, 0.01, 1.8, 12.0, 1.0 / 3.0, 0.003):
        assert real32(float(np.float32(v))) == pytest.approx(v, rel=1e-7)
    assert real32(float(np.float32(0.05))) == 0.05
    assert math.isnan(real32(math.nan))
