"""MAVLink 2 frames packed straight from a message's fields (the setpoint's hot path,
:meth:`onboard.link.px4.MavLink.send_fields`)."""

from __future__ import annotations

import struct

from .px4 import mavlink


class FrameEncoder:
    """MAVLink 2 frames of one message type, unsigned, packed directly from the fields in the
    order of the message's wire format (pymavlink's ``unpacker``; :meth:`MavLink.send_fields`):
    what pymavlink's ``<name>_encode`` then ``send`` put on the wire, byte for byte (trailing
    zeros of the payload trimmed, CRC with the message's CRC_EXTRA), without building a message
    object per frame."""

    def __init__(self, message_class) -> None:
        self.message_class = message_class
        self._payload = message_class.unpacker
        self._header = struct.Struct("<BBBBBBBHB")
        self._crc_extra = bytes([message_class.crc_extra])
        self._msg_id = message_class.id
        self._order = _wire_order(message_class)

    def frame(self, seq: int, system_id: int, component_id: int, fields) -> bytes:
        payload = self._payload.pack(*fields)
        n = len(payload)
        while n > 1 and payload[n - 1] == 0:
            n -= 1
        msg_id = self._msg_id
        head = self._header.pack(
            mavlink.PROTOCOL_MARKER_V2, n, 0, 0, seq, system_id, component_id,
            msg_id & 0xFFFF, msg_id >> 16,
        )  # fmt: skip
        body = head + payload[:n]
        crc = _crc16(body[1:] + self._crc_extra)
        return body + crc.to_bytes(2, "little")

    def message(self, *fields):
        """The pymavlink message of the same fields (for a signed link)."""
        flat = iter(fields)
        args: list = [None] * len(self._order)
        for i, count in self._order:
            args[i] = next(flat) if count == 0 else tuple(next(flat) for _ in range(count))
        return self.message_class(*args)


_MCRF4XX = getattr(mavlink, "mcrf4xx", None)  # fastcrc's, which pymavlink uses when installed


def _crc16(data: bytes) -> int:
    """MAVLink's CRC-16/MCRF4XX."""
    return _MCRF4XX(data, 0xFFFF) if _MCRF4XX is not None else mavlink.x25crc(data).crc


def _wire_order(message_class) -> list[tuple[int, int]]:
    """Per field in wire order: (its position in the constructor, array length or 0)."""
    names = message_class.fieldnames
    wire = message_class.ordered_fieldnames
    return [(names.index(n), k) for n, k in zip(wire, message_class.array_lengths, strict=True)]
