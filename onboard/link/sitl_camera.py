"""The SITL camera stream's wire format (TCP, little-endian), sent by ``groundstation sitl``
and read by ``onboard run --camera sitl://HOST:PORT``: per frame a 32-byte header
``magic b"PGF1", u32 seq, u16 width, u16 height, u32 payload bytes, f64 capture time (SITL
clock), f64 age at sending (s)`` followed by ``width * height * 3`` bytes of BGR pixels. The
age lets the receiver stamp the capture time on its own clock without sharing one with the
SITL."""

from __future__ import annotations

import struct

SITL_MAGIC = b"PGF1"
SITL_HEADER = struct.Struct("<4sIHHIdd")
MAX_SIDE_PX = 4096
MAX_AGE_S = 5.0


def pack_header(seq: int, width: int, height: int, capture_time_s: float, age_s: float) -> bytes:
    """The header of a ``width`` x ``height`` BGR frame."""
    n = width * height * 3
    return SITL_HEADER.pack(SITL_MAGIC, seq & 0xFFFFFFFF, width, height, n, capture_time_s, age_s)


def parse_header(data: bytes) -> tuple[int, int, int, float]:
    """(seq, width, height, age s) of a header; ValueError when it is not a consistent one."""
    magic, seq, w, h, n, _t_capture, age_s = SITL_HEADER.unpack(data)
    if magic != SITL_MAGIC or not (0 < w <= MAX_SIDE_PX and 0 < h <= MAX_SIDE_PX):
        raise ValueError("SITL camera stream: not a frame header")
    if n != w * h * 3 or not (0.0 <= age_s < MAX_AGE_S):
        raise ValueError("SITL camera stream: inconsistent frame header")
    return seq, w, h, age_s
