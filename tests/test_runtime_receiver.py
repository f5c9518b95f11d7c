"""PX4's stream parsed on the receiver thread (onboard/runtime/receiver.py): what the flight
controller sends reaches the tick's queue in order and intact, and the thread stops."""

from __future__ import annotations

import socket
import time

from onboard.link.px4 import MavLink, mavlink
from onboard.runtime.receiver import LinkReceiver


def _udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_messages_arrive_in_order_and_the_thread_stops():
    port = _udp_port()
    onboard = MavLink(f"udpin:127.0.0.1:{port}", 1, 191)
    px4 = MavLink(f"udpout:127.0.0.1:{port}", 1, 1)
    rx = LinkReceiver(onboard)
    rx.start()
    try:
        for k in range(20):
            px4.send(px4.mav.attitude_quaternion_encode(k, 1.0, 0.0, 0.0, 0.0, 0.1 * k, 0.0, 0.0))
        got: list = []
        end = time.monotonic() + 5.0
        while len(got) < 20 and time.monotonic() < end:
            got += rx.drain()
            time.sleep(0.01)
    finally:
        rx.stop()
        onboard.close()
        px4.close()
    assert not rx.is_alive()
    quats = [m for m in got if m.get_type() == "ATTITUDE_QUATERNION"]
    assert [m.time_boot_ms for m in quats] == list(range(20))
    assert abs(quats[7].rollspeed - 0.7) < 1e-6
    assert onboard.received["ATTITUDE_QUATERNION"] == 20
    assert rx.drain() == []
    assert quats[0].get_msgId() == mavlink.MAVLINK_MSG_ID_ATTITUDE_QUATERNION
