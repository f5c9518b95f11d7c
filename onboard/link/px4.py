"""The one module that speaks MAVLink 2 and converts between PX4's frames and ours.

PX4 reports the world in NED (x north, y east, z down) and the body in FRD (x forward, y right,
z down); the onboard loop works in ENU and FLU (DESIGN.md §1). Both conversions are fixed
axis permutations, each its own inverse. Quaternions are (w, x, y, z), body -> world.

:class:`MavLink` wraps a pymavlink connection so that nothing arriving on it can raise into
the caller: garbage and frames with a bad checksum or signature are counted and dropped, so
are duplicated and out-of-order frames, and a datagram peer that never sent one valid frame
is not answered.
"""

from __future__ import annotations

import contextlib
import math
import os
import socket
import struct
import sys
import threading
import time
from collections import Counter, deque
from collections.abc import Iterable
from typing import TYPE_CHECKING

import numpy as np

os.environ.setdefault("MAVLINK20", "1")  # before pymavlink picks its wire protocol

from pymavlink import mavutil

from ..constants import (  # declared there, imported from here too
    PX4_MAIN_AUTO,
    PX4_MAIN_OFFBOARD,
    PX4_MAIN_POSCTL,
    PX4_SUB_AUTO_LOITER,
)
from ..geometry import quat_to_rotmat, rotmat_to_quat
from .datagram import DatagramSender, sender_for

if TYPE_CHECKING:
    from .frame_encoder import FrameEncoder
    from .tlog import TlogWriter

mavutil.set_dialect("common")
mavlink = mavutil.mavlink

# ---------------------------------------------------------------------- identities
VEHICLE_SYSTEM_ID = 1
AUTOPILOT_COMPONENT_ID = mavlink.MAV_COMP_ID_AUTOPILOT1  # 1
ONBOARD_COMPONENT_ID = mavlink.MAV_COMP_ID_ONBOARD_COMPUTER  # 191
TARGET_SYSTEM_ID = 2  # a cooperative target (the SITL's, a target drone) reports itself here
GCS_SYSTEM_ID = 255
GCS_COMPONENT_ID = mavlink.MAV_COMP_ID_MISSIONPLANNER  # 190

# Operator commands to the onboard component (COMMAND_LONG, answered with COMMAND_ACK)
CMD_START = mavlink.MAV_CMD_USER_1  # 31010: arm, enter offboard and intercept
CMD_ABORT = mavlink.MAV_CMD_USER_2  # 31011: brake and hold, hand back to PX4 hold mode


DEFAULT_SITL_URL = "udpout:127.0.0.1:14540"  # PX4 SITL sends its offboard link to 14540
DEFAULT_ONBOARD_FC_URL = "udpin:127.0.0.1:14540"
DEFAULT_GCS_URL = "udpout:127.0.0.1:14550"  # ground stations listen on 14550


def px4_custom_mode(main_mode: int, sub_mode: int = 0) -> int:
    return (main_mode << 16) | (sub_mode << 24)


def px4_mode_name(custom_mode: int) -> str:
    main, sub = (custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF
    if main == PX4_MAIN_OFFBOARD:
        return "OFFBOARD"
    if main == PX4_MAIN_AUTO:
        return {PX4_SUB_AUTO_LOITER: "HOLD", 2: "TAKEOFF", 5: "RTL", 6: "LAND"}.get(
            sub, f"AUTO.{sub}"
        )
    if main == PX4_MAIN_POSCTL:
        return "POSCTL"
    return f"MODE.{main}"


MODE_OFFBOARD = px4_custom_mode(PX4_MAIN_OFFBOARD)
MODE_HOLD = px4_custom_mode(PX4_MAIN_AUTO, PX4_SUB_AUTO_LOITER)

# Linux's SO_TIMESTAMPNS (= SCM_TIMESTAMPNS; Python's socket module does not name it)
SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35 if sys.platform == "linux" else -1)

# ---------------------------------------------------------------------- frames
_NED_ENU = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
_FRD_FLU = np.diag([1.0, -1.0, -1.0])


def ned_to_enu(v_ned) -> np.ndarray:
    """A world vector from NED to ENU (and back: the swap is its own inverse)."""
    x, y, z = (float(c) for c in v_ned)
    return np.array([y, x, -z])


enu_to_ned = ned_to_enu


def frd_to_flu(v_frd) -> np.ndarray:
    """A body vector (or body rates) from FRD to FLU (its own inverse)."""
    x, y, z = (float(c) for c in v_frd)
    return np.array([x, -y, -z])


flu_to_frd = frd_to_flu


def quat_ned_frd_to_enu_flu(q_wxyz) -> np.ndarray:
    """PX4's attitude (FRD body -> NED world) as ours (FLU body -> ENU world)."""
    return rotmat_to_quat(_NED_ENU @ quat_to_rotmat(np.asarray(q_wxyz, float)) @ _FRD_FLU)


def quat_enu_flu_to_ned_frd(q_wxyz) -> np.ndarray:
    """Our attitude (FLU -> ENU) as PX4's (FRD -> NED)."""
    return rotmat_to_quat(_NED_ENU @ quat_to_rotmat(np.asarray(q_wxyz, float)) @ _FRD_FLU)


def all_finite(values: Iterable[float]) -> bool:
    try:
        return all(math.isfinite(float(v)) for v in values)
    except (TypeError, ValueError):
        return False


# ---------------------------------------------------------------------- the link
class LinkError(RuntimeError):
    """A connection string that cannot be opened."""


class MavLink:
    """A MAVLink 2 endpoint that never raises on what it receives.

    ``url`` is a pymavlink connection string: ``udpin:HOST:PORT``, ``udpout:HOST:PORT``,
    ``tcp:HOST:PORT``, ``tcpin:HOST:PORT`` or a serial device ``/dev/ttyUSB0,921600``.
    With ``signing_key`` (32 bytes) outgoing frames are signed and incoming ones must carry a
    valid signature, except the message ids in ``unsigned_ok`` (``None``: accept every unsigned
    frame, for a ground station that signs what it sends but reads forwarded telemetry).
    """

    def __init__(
        self,
        url: str,
        system_id: int,
        component_id: int,
        signing_key: bytes | None = None,
        unsigned_ok: Iterable[int] | None = (),
    ) -> None:
        self.url = url
        device, baud = url, 57600
        if "," in url and not url.startswith(("udp", "tcp")):
            device, _, b = url.partition(",")
            try:
                baud = int(b)
            except ValueError:
                raise LinkError(f"MAVLink URL {url!r}: baud rate {b!r} is not a number") from None
        try:
            self.conn = mavutil.mavlink_connection(
                device,
                baud=baud,
                source_system=system_id,
                source_component=component_id,
                dialect="common",
                autoreconnect=False,
            )
        except Exception as exc:  # pymavlink raises what the OS raised, or ValueError
            raise LinkError(f"cannot open MAVLink link {url!r}: {exc}") from None
        self.conn.first_byte = False  # never let a stray 0xFE switch us to MAVLink 1
        self._datagrams: DatagramSender | None = None  # send_fields's sends, the GIL held
        if isinstance(self.conn, mavutil.mavudp):  # the kernel stamps each datagram's arrival
            with contextlib.suppress(AttributeError, OSError):
                self.conn.port.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
            self._datagrams = sender_for(self.conn.port)
        self.conn.mav.robust_parsing = True
        if signing_key is not None:
            allowed = None if unsigned_ok is None else frozenset(unsigned_ok)
            self.conn.setup_signing(
                signing_key,
                sign_outgoing=True,
                allow_unsigned_callback=lambda _mav, msg_id: allowed is None or msg_id in allowed,
            )
        self.system_id = system_id
        self.component_id = component_id
        self.mav = self.conn.mav
        self.received: Counter = Counter()
        self.bad_frames = 0
        self.sent = 0
        self.send_errors = 0
        self._trusted: set = set()
        self._refused: set = set()
        self.refused_peers = 0
        self.duplicate_frames = 0  # the same frame again (a duplicated sequence number)
        self.stale_frames = 0  # older than one already received (out of order)
        self._recent: dict[tuple, deque[bytes]] = {}
        self._newest_s: dict[tuple, float] = {}
        self._rx_times: deque[tuple[float, str]] = deque()
        self._first_rx_s: float | None = None  # when the first valid frame came
        self.tlog: TlogWriter | None = None
        # sending is safe from several threads (the control thread's setpoints, the receiver
        # thread's TIMESYNC answers, the ground sender's telemetry): one frame at a time, so
        # sequence numbers and signing timestamps stay in order. A signed link also parses
        # under it (pymavlink moves the signing timestamp forward on a valid signed frame)
        self.send_lock = threading.Lock()
        self._parse_lock = self.send_lock if signing_key is not None else contextlib.nullcontext()

    # -------------------------------------------------------------- receive
    def poll(self, max_messages: int = 500) -> list:
        """Every valid message waiting now (never blocks, never raises)."""
        with self._parse_lock:
            if isinstance(self.conn, mavutil.mavudp):
                out = self._poll_datagrams(max_messages)
            else:
                out = self._poll_stream(max_messages)
        now = time.monotonic()
        for msg in out:
            if self._first_rx_s is None:
                self._first_rx_s = now
            self.received[msg.get_type()] += 1
            self._rx_times.append((now, msg.get_type()))
            if self.tlog is not None:
                self.tlog.write(msg.get_msgbuf())
        cutoff = now - 2.0
        while self._rx_times and self._rx_times[0][0] < cutoff:
            self._rx_times.popleft()
        return out

    def _poll_datagrams(self, max_messages: int) -> list:
        """UDP: each datagram parsed on its own (a frame never spans two), so one garbage
        datagram cannot swallow the next good one; a server answers only peers that have
        sent at least one valid frame."""
        conn, mav = self.conn, self.mav
        out: list = []
        realtime_minus_monotonic = time.time() - time.monotonic()
        while len(out) < max_messages:
            try:
                data, anc, _flags, addr = conn.port.recvmsg(65535, 64)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:  # ECONNREFUSED from an ICMP error, a closed socket: nothing to read
                break
            mav.buf = bytearray()
            mav.buf_index = 0
            mav.expected_length = mavlink.HEADER_LEN_V1 + 2
            mav.have_prefix_error = False
            try:
                msgs = mav.parse_buffer(data) or []
            except Exception:  # pymavlink could not survive this datagram: drop it
                msgs = []
            valid = [m for m in msgs if _known(m)]
            rx = _kernel_rx_s(anc, realtime_minus_monotonic)
            for m in valid:
                m.rx_monotonic_s = rx  # None where the kernel gave no timestamp
            if len(valid) < len(msgs) or not msgs:
                self.bad_frames += max(len(msgs) - len(valid), 1)
            valid = [m for m in valid if self._in_order(m, addr)]
            if conn.udp_server:
                if valid:
                    self._trusted.add(addr)
                    conn.clients.add(addr)
                    conn.clients_last_alive[addr] = time.time()
                elif addr not in self._trusted and addr not in self._refused:
                    self._refused.add(addr)
                    self.refused_peers += 1
            out += valid
        return out

    def _poll_stream(self, max_messages: int) -> list:
        """Serial and TCP: a byte stream, frames may span reads."""
        out: list = []
        idle = 0
        for _ in range(max_messages):
            try:
                msg = self.conn.recv_msg()
            except Exception:  # a malformed frame pymavlink could not survive: drop it
                self.bad_frames += 1
                msg = None
            if msg is None:
                idle += 1
                if idle >= 3:
                    break
                continue
            idle = 0
            if not _known(msg):
                self.bad_frames += 1
                continue
            if self._in_order(msg, None):
                out.append(msg)
        return out

    def _in_order(self, msg, peer) -> bool:
        """False, and counted, for a frame seen already (a duplicate: same bytes, sequence
        number included, as one of the sender's last few of that message) or one stamped
        older than the newest of its kind from its sender by less than a second (out of order;
        a larger step back is a restarted sender and is accepted)."""
        key = (peer, msg.get_srcSystem(), msg.get_srcComponent(), msg.get_msgId())
        frame = bytes(msg.get_msgbuf())
        recent = self._recent.get(key)
        if recent is None:
            recent = self._recent[key] = deque(maxlen=4)
        elif frame in recent:
            self.duplicate_frames += 1
            return False
        recent.append(frame)
        t_s = _stamp_s(msg)
        if t_s is not None:
            newest = self._newest_s.get(key)
            if newest is not None and newest - 1.0 <= t_s < newest:
                self.stale_frames += 1
                return False
            self._newest_s[key] = t_s
        return True

    def rates_hz(self) -> dict[str, float]:
        """Messages per second by type over the last two seconds."""
        times = list(self._rx_times)  # a copy: the deque may grow on another thread
        if not times:
            return {}
        span = min(2.0, max(time.monotonic() - self._first_rx_s, 1e-3))
        c = Counter(t for _, t in times)
        return {k: round(v / span, 1) for k, v in sorted(c.items())}

    # -------------------------------------------------------------- send
    def send(self, msg) -> bool:
        try:
            with self.send_lock:
                self.mav.send(msg)
                self.sent += 1
                if self.tlog is not None:
                    self.tlog.write(msg.get_msgbuf())
            return True
        except Exception:  # OSError, a closed socket or a full serial buffer: report, go on
            self.send_errors += 1
            return False

    def send_fields(self, encoder: FrameEncoder, *fields) -> bool:
        """Send one message of ``encoder``'s type from its fields in wire order (the hot path's
        :meth:`send`: no pymavlink message object; the same bytes on the wire). A signed link
        goes through pymavlink."""
        mav = self.mav
        if mav.signing.sign_outgoing or mav.send_callback is not None:
            return self.send(encoder.message(*fields))
        try:
            with self.send_lock:
                frame = encoder.frame(mav.seq, mav.srcSystem, mav.srcComponent, fields)
                mav.seq = (mav.seq + 1) % 256
                if not self._write_holding_gil(frame):
                    self.send_errors += 1  # refused by the kernel: lost, as on the way
                    return False
                mav.total_packets_sent += 1
                mav.total_bytes_sent += len(frame)
                self.sent += 1
                if self.tlog is not None:
                    self.tlog.write(frame)
            return True
        except Exception:  # as send(): report, go on
            self.send_errors += 1
            return False

    def _write_holding_gil(self, frame: bytes) -> bool:
        """Write ``frame`` as pymavlink would, but on a UDP link without giving the GIL away
        (datagram.py: the control thread's setpoint must not wait for another thread that
        took it). False when the kernel refused the datagram; other links, or a destination
        not yet an IPv4 address (pymavlink resolves it on its first write), go through
        pymavlink."""
        dest = self._datagram_dest()
        if dest is not None:
            try:
                return self._datagrams.send(frame, dest)
            except ValueError:  # a hostname: resolved by pymavlink's write below
                pass
        self.mav.file.write(frame)
        return True

    def _datagram_dest(self) -> tuple | None:
        """Where :meth:`_write_holding_gil` sends with libc's ``sendto``: a UDP link's one peer
        (a listening link's only client, or the address an outgoing one sends to), or None
        where pymavlink writes instead (not UDP, a listening link with no client or several,
        a broadcast link)."""
        conn, out = self.conn, self._datagrams
        if out is None:
            return None
        if conn.udp_server:
            clients = conn.clients
            return next(iter(clients)) if len(clients) == 1 else None  # else pymavlink's pick
        return None if conn.broadcast else conn.destination_addr

    def send_frame(self, frame: bytes) -> bool:
        """Pass an already-encoded frame on as it is (another link's message forwarded)."""
        try:
            with self.send_lock:
                self.conn.write(frame)
            return True
        except Exception:
            self.send_errors += 1
            return False

    def heartbeat(
        self, mav_type: int, autopilot: int, base_mode: int, custom_mode: int, system_status: int
    ) -> bool:
        return self.send(
            self.mav.heartbeat_encode(mav_type, autopilot, base_mode, custom_mode, system_status)
        )

    def statustext(self, severity: int, text: str) -> bool:
        return self.send(self.mav.statustext_encode(severity, text.encode("utf-8")[:50]))

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self.conn.close()


def _stamp_s(msg) -> float | None:
    """The sender's time stamp of a message in seconds, if it carries one."""
    t = getattr(msg, "time_usec", None)
    if isinstance(t, int) and t > 0:
        return t / 1e6
    t = getattr(msg, "time_boot_ms", None)
    if isinstance(t, int) and t > 0:
        return t / 1e3
    return None


def _kernel_rx_s(ancillary, realtime_minus_monotonic: float) -> float | None:
    """A datagram's SO_TIMESTAMPNS arrival (realtime) on the monotonic clock."""
    for level, kind, data in ancillary:
        if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS:
            sec, nsec = struct.unpack("qq", data[:16])
            return sec + 1e-9 * nsec - realtime_minus_monotonic
    return None


def _known(msg) -> bool:
    """A frame pymavlink could check: not garbage, and an id of the dialect (an unknown id
    carries no CRC seed, so random bytes pass as one)."""
    kind = msg.get_type()
    return kind != "BAD_DATA" and not kind.startswith("UNKNOWN")


def load_signing_key(path: str) -> bytes:
    """A MAVLink 2 signing key: a file holding 64 hex digits (32 bytes)."""
    try:
        with open(path, encoding="ascii") as f:
            text = f.read().strip()
    except (OSError, UnicodeDecodeError) as exc:
        raise LinkError(f"signing key {path}: cannot read: {exc}") from None
    try:
        key = bytes.fromhex(text)
    except ValueError:
        key = b""
    if len(key) != 32:
        raise LinkError(f"signing key {path}: expected 64 hex digits (32 bytes)")
    return key


def message_text(msg) -> str:
    """STATUSTEXT text as a str (pymavlink gives str or bytes, NUL padded)."""
    t = msg.text
    if isinstance(t, bytes):
        t = t.decode("utf-8", "replace")
    return t.rstrip("\x00")


def real32(value: float) -> float:
    """A REAL32 parameter value as the decimal it was meant to be (0.05, not 0.0500000007):
    seven significant digits are what a float32 carries."""
    value = float(value)
    return float(f"{value:.7g}") if math.isfinite(value) else value


def param_id_str(param_id) -> str:
    if isinstance(param_id, bytes):
        param_id = param_id.decode("ascii", "replace")
    return param_id.rstrip("\x00")
