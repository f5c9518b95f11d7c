"""H.264 over RTP (RFC 6184: single NAL units and FU-A fragments, STAP-A received, payload
type 96, 90 kHz clock): the onboard camera's video stream on the wire, packed by
``onboard run --video`` and unpacked by the ground station. The RTP timestamp is the capture
time on the wall clock (90 kHz, modulo 2^32), so a receiver on a clock-synchronised machine
reads the glass-to-glass latency off each frame."""

from __future__ import annotations

import random
import struct
from dataclasses import dataclass

PAYLOAD_TYPE = 96  # dynamic, H.264 (QGC's and GStreamer's default caps)
RTP_CLOCK_HZ = 90_000
MAX_PAYLOAD = 1200  # bytes of NAL data per RTP packet: below any path MTU
_RTP = struct.Struct("!BBHII")
_FU_A, _STAP_A = 28, 24
NAL_IDR, NAL_SPS = 5, 7


def split_annexb(data: bytes) -> list[bytes]:
    """NAL units of an Annex-B byte stream (start codes 00 00 01 / 00 00 00 01 removed)."""
    out, i, n = [], 0, len(data)
    starts = []
    while True:
        j = data.find(b"\x00\x00\x01", i)
        if j < 0:
            break
        starts.append(j + 3)
        i = j + 3
    for k, s in enumerate(starts):
        end = starts[k + 1] - 3 if k + 1 < len(starts) else n
        nal = data[s:end]
        if k + 1 < len(starts) and nal.endswith(b"\x00"):  # a 4-byte start code's zero
            nal = nal[:-1]
        if nal:
            out.append(nal)
    return out


class RtpPacketizer:
    """Access units (Annex-B) to RTP packets."""

    def __init__(self, ssrc: int | None = None, seq: int | None = None) -> None:
        rng = random.Random()
        self.ssrc = rng.getrandbits(32) if ssrc is None else ssrc
        self.seq = rng.getrandbits(16) if seq is None else seq

    def _packet(self, marker: bool, ts: int, payload: bytes) -> bytes:
        head = _RTP.pack(0x80, (0x80 if marker else 0) | PAYLOAD_TYPE, self.seq, ts, self.ssrc)
        self.seq = (self.seq + 1) & 0xFFFF
        return head + payload

    def packets(self, access_unit: bytes, ts: int) -> list[bytes]:
        ts &= 0xFFFFFFFF
        nals = split_annexb(access_unit)
        out: list[bytes] = []
        for k, nal in enumerate(nals):
            last = k == len(nals) - 1
            if len(nal) <= MAX_PAYLOAD:
                out.append(self._packet(last, ts, nal))
                continue
            indicator = (nal[0] & 0xE0) | _FU_A
            kind = nal[0] & 0x1F
            body = nal[1:]
            chunks = [body[i : i + MAX_PAYLOAD] for i in range(0, len(body), MAX_PAYLOAD)]
            for c, chunk in enumerate(chunks):
                start, end = c == 0, c == len(chunks) - 1
                header = (0x80 if start else 0) | (0x40 if end else 0) | kind
                out.append(self._packet(last and end, ts, bytes((indicator, header)) + chunk))
        return out


@dataclass(frozen=True)
class AccessUnit:
    data: bytes  # Annex-B
    rtp_ts: int
    keyframe: bool  # holds an IDR slice or a sequence parameter set


class RtpDepacketizer:
    """RTP packets to whole access units; after a lost packet, nothing until the next
    keyframe (a decoder fed a broken reference chain shows garbage)."""

    def __init__(self) -> None:
        self._seq: int | None = None
        self._ts: int | None = None
        self._nals: list[bytes] = []
        self._fu: bytearray | None = None
        self._broken = True  # wait for a keyframe first
        self.lost = 0  # packets missing from the sequence

    def _emit(self) -> AccessUnit | None:
        nals, self._nals, ts = self._nals, [], self._ts
        self._fu = None
        if not nals:
            return None
        key = any(n[0] & 0x1F in (NAL_IDR, NAL_SPS) for n in nals)
        if self._broken and not key:
            return None
        self._broken = False
        return AccessUnit(b"".join(b"\x00\x00\x00\x01" + n for n in nals), ts, key)

    def push(self, packet: bytes) -> AccessUnit | None:
        """One datagram; the access unit it completes, if any."""
        if len(packet) < _RTP.size + 1 or packet[0] >> 6 != 2:
            return None
        b0, b1, seq, ts, _ssrc = _RTP.unpack_from(packet)
        if b1 & 0x7F != PAYLOAD_TYPE:
            return None
        head = _RTP.size + 4 * (b0 & 0x0F)
        if b0 & 0x10:  # header extension
            if len(packet) < head + 4:
                return None
            head += 4 + 4 * struct.unpack_from("!H", packet, head + 2)[0]
        end = len(packet) - (packet[-1] if b0 & 0x20 else 0)
        payload = packet[head:end]
        done: AccessUnit | None = None
        if self._ts is not None and ts != self._ts:  # a new frame: the last one ended unmarked
            done = self._emit()
        if self._seq is not None and seq != (self._seq + 1) & 0xFFFF:
            self.lost += (seq - self._seq - 1) & 0xFFFF
            self._broken = True
            self._nals, self._fu = [], None
        self._seq, self._ts = seq, ts
        if payload:
            kind = payload[0] & 0x1F
            if kind == _FU_A and len(payload) > 2:
                fu = payload[1]
                if fu & 0x80:
                    self._fu = bytearray(((payload[0] & 0xE0) | (fu & 0x1F),))
                if self._fu is not None:
                    self._fu += payload[2:]
                    if fu & 0x40:
                        self._nals.append(bytes(self._fu))
                        self._fu = None
            elif kind == _STAP_A:
                i = 1
                while i + 2 <= len(payload):
                    (size,) = struct.unpack_from("!H", payload, i)
                    self._nals.append(payload[i + 2 : i + 2 + size])
                    i += 2 + size
            elif 1 <= kind <= 23:
                self._nals.append(payload)
        if b1 & 0x80:  # marker: the frame's last packet (newer than an unmarked one before)
            au = self._emit()
            self._ts = None
            return au or done
        return done


def rtp_ts_of(wall_s: float) -> int:
    return round(wall_s * RTP_CLOCK_HZ) & 0xFFFFFFFF


def age_of_rtp_ts(rtp_ts: int, now_wall_s: float) -> float:
    """Seconds from the RTP timestamp (a wall-clock capture time) to ``now_wall_s``."""
    return ((rtp_ts_of(now_wall_s) - rtp_ts) & 0xFFFFFFFF) / RTP_CLOCK_HZ
