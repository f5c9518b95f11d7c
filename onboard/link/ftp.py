"""A read-only MAVLink FTP server (https://mavlink.io/en/services/ftp.html) over a few virtual
files, as ground stations use it to fetch parameters and component metadata.

:class:`FtpServer` is pure: :meth:`FtpServer.handle` takes the 251-byte
``FILE_TRANSFER_PROTOCOL`` payload of a request and returns the reply payloads; the caller owns
the link (:func:`serve`). Every request gets an answer at once: what it cannot do (write,
create, remove, an unknown opcode) is a NAK, so a client falls back without waiting.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Iterable

HEADER = struct.Struct("<HBBBBBBI")  # seq, session, opcode, size, req_opcode, burst, pad, offset
PAYLOAD_LEN = 251
DATA_MAX = PAYLOAD_LEN - HEADER.size  # 239

OP_TERMINATE_SESSION = 1
OP_RESET_SESSIONS = 2
OP_LIST_DIRECTORY = 3
OP_OPEN_FILE_RO = 4
OP_READ_FILE = 5
OP_BURST_READ_FILE = 15
OP_ACK = 128
OP_NAK = 129

ERR_FAIL = 1
ERR_INVALID_DATA_SIZE = 3
ERR_INVALID_SESSION = 4
ERR_NO_SESSIONS_AVAILABLE = 5
ERR_EOF = 6
ERR_UNKNOWN_COMMAND = 7
ERR_FILE_NOT_FOUND = 10

MAX_SESSIONS = 4


class FtpServer:
    """``read(path)`` gives a file's bytes or ``None``; ``names`` are listed in directories.
    A file's contents are taken once, when it is opened, so a read never sees two versions.
    Sessions carry the id the client put in its open request (as ArduPilot's server does)."""

    def __init__(self, read: Callable[[str], bytes | None], names: Iterable[str]) -> None:
        self.read = read
        self.names = tuple(names)
        self.sessions: dict[int, bytes] = {}  # by the session id the client chose
        self.paths: dict[int, str] = {}

    def handle(self, payload: bytes) -> list[bytes]:
        if len(payload) < HEADER.size:
            return []
        seq, session, opcode, size, _req, _burst, _pad, offset = HEADER.unpack_from(payload)
        data = bytes(payload[HEADER.size : HEADER.size + min(size, DATA_MAX)])
        reply_seq = (seq + 1) & 0xFFFF

        def ack(body: bytes = b"", burst: int = 0, at: int = offset, n: int = 0) -> bytes:
            head = HEADER.pack((reply_seq + n) & 0xFFFF, session, OP_ACK, len(body), opcode,
                               burst, 0, at)  # fmt: skip
            return head + body

        def nak(error: int) -> list[bytes]:
            return [
                HEADER.pack(reply_seq, session, OP_NAK, 1, opcode, 0, 0, offset) + bytes([error])
            ]

        if opcode == OP_RESET_SESSIONS:
            self.sessions.clear()
            self.paths.clear()
            return [ack()]
        if opcode == OP_TERMINATE_SESSION:
            self.paths.pop(session, None)
            if self.sessions.pop(session, None) is None:
                return nak(ERR_INVALID_SESSION)
            return [ack()]
        if opcode == OP_OPEN_FILE_RO:
            path = data.split(b"\0")[0].decode("utf-8", "replace")
            open_path = self.paths.get(session)
            if open_path == path:  # a retried open (its ACK was lost): the same answer
                return [ack(struct.pack("<I", len(self.sessions[session])), at=0)]
            if open_path is not None or len(self.sessions) >= MAX_SESSIONS:
                return nak(ERR_NO_SESSIONS_AVAILABLE)
            contents = self.read(path)
            if contents is None:
                return nak(ERR_FILE_NOT_FOUND)
            self.sessions[session], self.paths[session] = contents, path
            return [ack(struct.pack("<I", len(contents)), at=0)]
        if opcode in (OP_READ_FILE, OP_BURST_READ_FILE):
            contents = self.sessions.get(session)
            if contents is None:
                return nak(ERR_INVALID_SESSION)
            if offset >= len(contents):
                return nak(ERR_EOF)
            chunk = max(1, min(size or DATA_MAX, DATA_MAX))
            if opcode == OP_READ_FILE:
                return [ack(contents[offset : offset + chunk])]
            starts = range(offset, len(contents), chunk)
            return [
                ack(contents[at : at + chunk], burst=int(at + chunk >= len(contents)), at=at, n=i)
                for i, at in enumerate(starts)
            ]
        if opcode == OP_LIST_DIRECTORY:
            path = data.split(b"\0")[0].decode("utf-8", "replace").strip("/")
            entries = self._list(path)
            if entries is None:
                return nak(ERR_FILE_NOT_FOUND)
            if offset >= len(entries):
                return nak(ERR_EOF)
            body = b""
            for entry in entries[offset:]:
                if len(body) + len(entry) > DATA_MAX:
                    break
                body += entry
            return [ack(body)]
        return nak(ERR_UNKNOWN_COMMAND)

    def _list(self, path: str) -> list[bytes] | None:
        """Directory entries as FTP lists them: ``F<name>\\t<size>\\0`` or ``D<name>\\0``."""
        out, dirs = [], []
        for name in self.names:
            parent, _, leaf = name.rpartition("/")
            if parent == path:
                size = len(self.read(name) or b"")
                out.append(f"F{leaf}\t{size}\0".encode())
            elif path == "" and parent and parent not in dirs:
                dirs.append(parent)
                out.append(f"D{parent}\0".encode())
        if not out and path not in ("", *dirs):
            return None
        return out


def serve(server: FtpServer, link, msg, system_id: int, component_id: int) -> None:
    """Answer one ``FILE_TRANSFER_PROTOCOL`` message addressed to us on ``link`` (a
    :class:`onboard.link.px4.MavLink`)."""
    if msg.target_system != system_id or msg.target_component not in (component_id, 0):
        return
    for reply in server.handle(bytes(msg.payload)):
        body = reply + bytes(PAYLOAD_LEN - len(reply))
        link.send(
            link.mav.file_transfer_protocol_encode(
                0, msg.get_srcSystem(), msg.get_srcComponent(), body
            )
        )
