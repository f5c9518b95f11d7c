"""A UDP datagram sent without giving the GIL away (Linux): the control thread's setpoint.

Python's ``socket.sendto`` releases the GIL around the system call. Another thread of the
process that wants it then (a link's receiver just woken by a datagram, the camera thread
after a detection) takes it and runs until it blocks or its switch interval (0.5 ms on the
onboard runtime) is up, and the control thread, its send done, waits for it: in ``groundstation
bench --sitl`` on the 2-core machine here 7-11 % of the setpoint sends took more than 0.15 ms
of wall time (a median 0.22 ms, up to 0.8 ms) for 0.04 ms of CPU, the largest part of the
tick's work tail. libc's ``sendto``
called through :class:`ctypes.PyDLL` keeps the GIL for the call (some 30-40 us on loopback);
``MSG_DONTWAIT`` makes sure the call never blocks while it holds it: a full send buffer drops
the datagram with ``EAGAIN`` and the caller counts it, as it would a datagram lost on the way
(the next setpoint follows a period later), instead of holding the whole process.

IPv4 destinations only (pymavlink's UDP links are IPv4); elsewhere (not Linux, no libc) the
caller falls back to ``socket.sendto``: :func:`sender_for` returns None.
"""

from __future__ import annotations

import ctypes
import errno
import socket
import struct
import sys
from collections.abc import Callable

_MSG_DONTWAIT = getattr(socket, "MSG_DONTWAIT", 0)


def _libc_sendto() -> Callable[..., int] | None:
    """libc's ``sendto`` as a function that holds the GIL while it runs, or None."""
    if not sys.platform.startswith("linux") or not _MSG_DONTWAIT:
        return None
    try:
        fn = ctypes.PyDLL(None, use_errno=True).sendto  # PyDLL: the GIL stays held
    except (OSError, AttributeError):
        return None
    fn.argtypes = (
        ctypes.c_int, ctypes.c_char_p, ctypes.c_size_t, ctypes.c_int, ctypes.c_char_p,
        ctypes.c_uint32,
    )  # fmt: skip
    fn.restype = ctypes.c_ssize_t
    return fn


_SENDTO = _libc_sendto()


def sockaddr_in(host: str, port: int) -> bytes:
    """Linux's ``struct sockaddr_in`` for an IPv4 address and port (16 bytes). ValueError
    for anything else (a hostname, IPv6, a port out of range)."""
    try:
        packed = socket.inet_pton(socket.AF_INET, host)
    except (OSError, TypeError) as exc:
        raise ValueError(f"not an IPv4 address: {host!r}") from exc
    if not 0 <= port <= 0xFFFF:
        raise ValueError(f"port out of range: {port}")
    return struct.pack("=H", socket.AF_INET) + struct.pack("!H", port) + packed + bytes(8)


class DatagramSender:
    """Sends datagrams on ``sock`` (a UDP socket) with the GIL held. :meth:`send` returns
    True when the kernel took the datagram, False when it refused it (``errno`` in
    :attr:`last_errno`: a full buffer, an unreachable address, the socket closed)."""

    def __init__(self, sock: socket.socket, sendto: Callable[..., int]) -> None:
        self._sock = sock
        self._sendto = sendto
        self._addr_key: tuple[str, int] | None = None  # the last address sent to
        self._addr = b""
        self.last_errno = 0

    def send(self, frame: bytes, address: tuple[str, int]) -> bool:
        """Send ``frame`` to ``address`` (IPv4 host, port); ValueError for another address."""
        if address != self._addr_key:
            self._addr = sockaddr_in(*address)
            self._addr_key = address
        return self.send_to(frame, self._addr)

    @property
    def address(self) -> tuple[str, int] | None:
        """The (IPv4 host, port) :meth:`send` last took (None before it took one)."""
        return self._addr_key

    def send_to(self, frame: bytes, sockaddr: bytes) -> bool:
        """Send ``frame`` to ``sockaddr`` (a :func:`sockaddr_in`): :meth:`send`'s system call."""
        fd = self._sock.fileno()  # -1 once closed: never a number since reused by another file
        if fd < 0:
            self.last_errno = errno.EBADF
            return False
        n = self._sendto(fd, frame, len(frame), _MSG_DONTWAIT, sockaddr, len(sockaddr))
        if n < 0:
            self.last_errno = ctypes.get_errno()
            return False
        return True


def sender_for(sock: socket.socket) -> DatagramSender | None:
    """A :class:`DatagramSender` for an IPv4 UDP socket, or None where this is not available
    (not Linux, no libc's ``sendto``, another kind of socket)."""
    if _SENDTO is None or sock.family != socket.AF_INET or sock.type != socket.SOCK_DGRAM:
        return None
    return DatagramSender(sock, _SENDTO)
