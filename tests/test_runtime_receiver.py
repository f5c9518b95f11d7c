"""PX4's stream parsed on the receiver thread (onboard/runtime/receiver.py): what the flight
controller sends reaches the tick's queue (or the handler) in order and intact, and the thread
stops; the work the tick hands off (onboard/runtime/sender.py) runs in order."""

from __future__ import annotations

import socket
import threading
import time

from onboard.link.px4 import MavLink, mavlink
from onboard.runtime.receiver import LinkReceiver
from onboard.runtime.sender import Sender


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


def test_batches_go_to_the_handler_and_a_failing_handler_does_not_stop_the_thread():
    port = _udp_port()
    onboard = MavLink(f"udpin:127.0.0.1:{port}", 1, 191)
    px4 = MavLink(f"udpout:127.0.0.1:{port}", 1, 1)
    got: list = []
    errors: list[str] = []

    calls: list[int] = []

    def take(msgs: list) -> None:
        got.extend(msgs)
        calls.append(len(msgs))
        if len(calls) == 1:
            raise ValueError("a handler's bug")

    rx = LinkReceiver(onboard, take, errors.append)
    rx.start()
    try:
        for k in range(10):
            px4.send(px4.mav.attitude_quaternion_encode(k, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
            time.sleep(0.002)
        end = time.monotonic() + 5.0
        while len(got) < 10 and time.monotonic() < end:
            time.sleep(0.01)
    finally:
        rx.stop()
        onboard.close()
        px4.close()
    assert [m.time_boot_ms for m in got] == list(range(10))
    assert rx.errors == 1 and errors == ["receiver: ValueError: a handler's bug"]
    assert rx.drain() == []  # nothing queued: the handler had every message


def test_the_sender_runs_work_in_order_after_the_caller_and_inline_when_stopped():
    done: list[tuple[int, str]] = []
    errors: list[str] = []
    sender = Sender(errors.append)
    sender.submit(done.append, (0, threading.current_thread().name))  # not started: inline
    sender.start()
    for k in range(1, 50):
        sender.submit(lambda k=k: done.append((k, threading.current_thread().name)))
    sender.submit(lambda: 1 / 0)
    sender.submit(lambda: done.append((50, threading.current_thread().name)))
    sender.stop()
    assert not sender.is_alive()
    assert [k for k, _ in done] == list(range(51))
    assert {name for _, name in done[1:]} == {"sender"} and done[0][1] != "sender"
    assert sender.errors == 1 and errors == ["sender: ZeroDivisionError: division by zero"]
    sender.submit(done.append, (51, threading.current_thread().name))
    assert done[-1][0] == 51  # stopped: inline again
