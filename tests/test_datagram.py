"""The setpoint's datagram sent with the GIL held (onboard/link/datagram.py): the
bytes that arrive are the frame, a refusal is counted and never raises, a closed socket is
never written to, and the MavLink link uses it for its UDP links and pymavlink otherwise."""

from __future__ import annotations

import ctypes
import errno
import socket
import sys
import time

import pytest

from onboard.link import datagram
from onboard.link.datagram import DatagramSender, sender_for, sockaddr_in
from onboard.link.px4 import MavLink, mavlink
from onboard.runtime.fc_side import SET_ATTITUDE_TARGET

from .sitl_rig import free_port

LINUX = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="Linux's libc sendto")


def _receiver() -> tuple[socket.socket, int]:
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.settimeout(5.0)
    return rx, rx.getsockname()[1]


def test_sockaddr_in_is_linuxs_struct_and_refuses_what_is_not_ipv4():
    addr = sockaddr_in("127.0.0.1", 14540)
    assert len(addr) == 16
    assert int.from_bytes(addr[:2], sys.byteorder) == socket.AF_INET
    assert addr[2:4] == (14540).to_bytes(2, "big") and addr[4:8] == bytes((127, 0, 0, 1))
    assert addr[8:] == bytes(8)
    for host, port in (("localhost", 1), ("::1", 1), ("127.1", 1), ("127.0.0.1", 70000)):
        with pytest.raises(ValueError):
            sockaddr_in(host, port)


@LINUX
def test_libc_sendto_is_called_with_the_gil_held():
    fn = datagram._SENDTO
    assert fn is not None
    # ctypes releases the GIL around a foreign call unless the library was loaded as PyDLL
    assert type(fn)._flags_ & ctypes._FUNCFLAG_PYTHONAPI


@LINUX
def test_a_datagram_arrives_as_the_frame_it_was():
    rx, port = _receiver()
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        out = sender_for(tx)
        assert out is not None
        frames = [bytes(range(k, k + 40)) for k in range(3)]
        for frame in frames:
            assert out.send(frame, ("127.0.0.1", port))
        assert [rx.recvfrom(2048)[0] for _ in frames] == frames
    finally:
        rx.close()
        tx.close()


@LINUX
def test_a_closed_socket_is_never_written_to_and_a_refusal_is_reported():
    rx, port = _receiver()
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    out = sender_for(tx)
    tx.close()
    assert out.send(b"x" * 20, ("127.0.0.1", port)) is False
    assert out.last_errno == errno.EBADF
    rx.close()

    def refusing(*_args) -> int:  # the kernel's answer to a full send buffer
        ctypes.set_errno(errno.EAGAIN)
        return -1

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        full = DatagramSender(s, refusing)
        assert full.send(b"x" * 20, ("127.0.0.1", port)) is False
        assert full.last_errno == errno.EAGAIN


def test_no_sender_for_a_socket_it_cannot_serve():
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as tcp:
        assert sender_for(tcp) is None
    with socket.socket(socket.AF_INET6, socket.SOCK_DGRAM) as v6:
        assert sender_for(v6) is None


_SETPOINT = (1.0, 0.0, 0.0, 0.0, 0.1, -0.2, 0.3, 0.55, 1, 1, 7)  # after time_boot_ms


def _setpoint(link: MavLink, t_ms: int) -> bool:
    return link.send_fields(SET_ATTITUDE_TARGET, t_ms, *_SETPOINT)


def _decode(frame: bytes):
    mav = mavlink.MAVLink(None)
    return mav.parse_char(frame)


@LINUX
@pytest.mark.parametrize("host", ["127.0.0.1", "localhost"])
def test_a_udp_link_sends_its_setpoints_with_the_gil_held_and_they_decode(monkeypatch, host):
    rx, port = _receiver()
    link = MavLink(f"udpout:{host}:{port}", 1, 191)
    calls = []
    real = link._datagrams.send

    def send(frame: bytes, dest: tuple[str, int]) -> bool:
        sent = real(frame, dest)  # raises ValueError for a hostname
        calls.append(dest)
        return sent

    monkeypatch.setattr(link._datagrams, "send", send)
    try:
        for t_ms in (10, 15, 20):
            assert _setpoint(link, t_ms)
        got = [_decode(rx.recvfrom(2048)[0]) for _ in range(3)]
        assert [m.time_boot_ms for m in got] == [10, 15, 20]
        assert [m.get_seq() for m in got] == [0, 1, 2]
        assert got[0].body_yaw_rate == pytest.approx(0.3) and got[0].thrust == pytest.approx(0.55)
        # an address goes straight to libc; a hostname once through pymavlink (which
        # resolves it), then straight too
        assert len(calls) == (3 if host == "127.0.0.1" else 2)
        assert all(c == ("127.0.0.1", port) for c in calls)
        assert link.sent == 3 and link.send_errors == 0
    finally:
        link.close()
        rx.close()


@LINUX
def test_a_refused_setpoint_is_counted_not_raised(monkeypatch):
    link = MavLink(f"udpout:127.0.0.1:{free_port()}", 1, 191)
    try:
        monkeypatch.setattr(link._datagrams, "send", lambda *_a: False)
        assert _setpoint(link, 10) is False
        assert link.send_errors == 1 and link.sent == 0
    finally:
        link.close()


@LINUX
def test_a_listening_link_answers_its_one_client_with_the_gil_held(monkeypatch):
    port = free_port()
    onboard = MavLink(f"udpin:127.0.0.1:{port}", 1, 191)
    px4 = MavLink(f"udpout:127.0.0.1:{port}", 1, 1)
    sent_to = []
    real = onboard._datagrams.send
    monkeypatch.setattr(
        onboard._datagrams, "send", lambda frame, dest: sent_to.append(dest) or real(frame, dest)
    )
    try:
        assert _setpoint(onboard, 5) is True  # no client yet: pymavlink's write, to no one
        assert sent_to == []
        px4.send(px4.mav.heartbeat_encode(2, 12, 0, 0, 0))
        end = time.monotonic() + 5.0
        while not onboard.poll() and time.monotonic() < end:
            time.sleep(0.005)
        assert _setpoint(onboard, 10)
        assert sent_to == [("127.0.0.1", px4.conn.port.getsockname()[1])]
        end = time.monotonic() + 5.0
        got = []
        while not got and time.monotonic() < end:
            got = [m for m in px4.poll() if m.get_type() == "SET_ATTITUDE_TARGET"]
            time.sleep(0.005)
        assert [m.time_boot_ms for m in got] == [10]
    finally:
        onboard.close()
        px4.close()
