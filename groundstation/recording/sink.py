"""Where a recorder's messages go: an MCAP file written in this process
(:class:`LocalSink`) or in the recording process (:class:`ProcessSink`), one per Python
process, started on first use, which takes the MCAP encoding, chunk compression and disk
writes off the simulation's thread.

Both speak the same small interface (``add``, ``add_many``, ``metadata``, ``attachment``,
``finish``) with channels named by their index in :data:`~.schemas.CHANNELS`; a failure (a
full disk) surfaces as :class:`OSError` from the next call, never as a crash. The recording
process finishes every file it holds if this process dies, so a crashed sortie still leaves a
complete, indexed file marked INCOMPLETE.
"""

from __future__ import annotations

import atexit
import contextlib
import itertools
import os
import pickle
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

from mcap.writer import CompressionType, Writer

from onboard.channels.encode import RAW, encode
from onboard.channels.schemas import CHANNELS, schema_bytes

from .. import __version__ as gs_version

CHUNK_BYTES = 256 * 1024
BATCH = 64  # messages per hand-over: small, so little is left to write at the finish
FINISH_TIMEOUT_S = 60.0
_CRASH_OUTCOME = {"outcome": '"INCOMPLETE"', "reason": '"the recording process ended"'}


class McapFile:
    """One chunked, indexed, zstd MCAP file with every channel of :data:`CHANNELS`."""

    def __init__(self, path: Path, fileobj=None) -> None:
        self.path = Path(path)
        self._file = fileobj if fileobj is not None else open(path, "r+b")  # noqa: SIM115
        self._w = Writer(
            self._file,
            chunk_size=CHUNK_BYTES,
            compression=CompressionType.ZSTD,
            enable_data_crcs=True,  # DataEnd carries the CRC of the whole data section
        )
        self._w.start(profile="", library=f"peregrine {gs_version}")
        schema_ids: dict[str, int] = {}
        self.channel_ids: list[int] = []
        for topic, schema in CHANNELS:
            if schema not in schema_ids:
                schema_ids[schema] = self._w.register_schema(
                    schema, "jsonschema", schema_bytes(schema)
                )
            self.channel_ids.append(self._w.register_channel(topic, "json", schema_ids[schema]))

    def add_many(self, items) -> None:
        """(channel index, log time ns, encoder, payload) items; see :mod:`.encode`."""
        add, ids = self._w.add_message, self.channel_ids
        for ti, ns, enc, payload in items:
            add(ids[ti], ns, encode(enc, payload), ns)

    def metadata(self, name: str, data: dict[str, str]) -> None:
        self._w.add_metadata(name, data)

    def attachment(self, name: str, media_type: str, data: bytes) -> None:
        self._w.add_attachment(0, 0, name, media_type, data)

    def flush(self) -> None:
        self._file.flush()

    def finish(self) -> None:
        self._w.finish()
        self._file.close()

    def abandon(self) -> None:
        with contextlib.suppress(OSError):
            self._file.close()


class LocalSink:
    """The file written in this process."""

    def __init__(self, path: Path, fileobj) -> None:
        self._f = McapFile(path, fileobj)

    @property
    def file(self):  # the open file (tests simulate a full disk through it)
        return self._f._file

    def add(self, ti: int, ns: int, data: bytes) -> None:
        self._f.add_many(((ti, ns, RAW, data),))

    def add_many(self, ns: int, items) -> None:
        """(channel index, encoder, payload) items at one log time."""
        self._f.add_many((ti, ns, enc, payload) for ti, enc, payload in items)

    def metadata(self, name: str, data: dict[str, str]) -> None:
        self._f.metadata(name, data)

    def attachment(self, name: str, media_type: str, data: bytes) -> None:
        self._f.attachment(name, media_type, data)

    def started(self) -> None:
        self._f.flush()

    def finish(self, outcome: dict[str, str]) -> None:
        self._f.metadata("outcome", outcome)
        self._f.finish()

    def abandon(self) -> None:
        self._f.abandon()


# ---------------------------------------------------------------------- the recording process
_LEN = struct.Struct("<I")


def _frames(stream):
    """Length-prefixed pickles from a binary stream, until it ends."""
    while True:
        head = stream.read(_LEN.size)
        if len(head) < _LEN.size:
            return
        (n,) = _LEN.unpack(head)
        body = stream.read(n)
        if len(body) < n:
            return
        yield pickle.loads(body)


def _serve(requests, responses) -> None:
    """Serve requests until "stop" or the end of the stream (the owner died: what it sent
    before is still in the pipe and gets written, then every open file is finished)."""

    def answer(*msg) -> None:
        data = pickle.dumps(msg)
        with contextlib.suppress(OSError, ValueError):  # the owner may be gone: write on
            responses.write(_LEN.pack(len(data)) + data)
            responses.flush()

    files: dict[int, McapFile] = {}
    failed: dict[int, str] = {}
    for req in _frames(requests):
        kind = req[0]
        if kind == "stop":
            break
        fid = req[1]
        if fid in failed:
            if kind == "finish":
                answer("done", fid, failed.pop(fid))
            continue
        try:
            if kind == "open":
                files[fid] = McapFile(req[2])
            elif kind == "msgs":
                files[fid].add_many(req[2])
            elif kind == "meta":
                files[fid].metadata(req[2], req[3])
            elif kind == "attach":
                files[fid].attachment(req[2], req[3], req[4])
            elif kind == "flush":
                files[fid].flush()
            elif kind == "finish":
                f = files.pop(fid)
                f.metadata("outcome", req[2])
                f.finish()
                answer("done", fid, None)
        except (OSError, ValueError, KeyError) as exc:
            msg = f"{type(exc).__name__}: {exc}"
            f = files.pop(fid, None)
            if f is not None:
                f.abandon()
            answer("error", fid, msg)
            if kind == "finish":
                answer("done", fid, msg)
            else:
                failed[fid] = msg
    for f in files.values():
        with contextlib.suppress(OSError, ValueError):
            f.metadata("outcome", _CRASH_OUTCOME)
            f.finish()


class _RecordingProcess:
    """The one recording process of this Python process (``python -m
    groundstation.recording.sink``), fed through its stdin: length-prefixed pickles written
    synchronously, so what a sortie sent is in the kernel's buffer even if this process dies
    the next instant; its answers come back on its stdout, read by a thread."""

    def __init__(self) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "groundstation.recording.sink"],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            close_fds=True,
        )
        self._ids = itertools.count(1)
        self._lock = threading.Condition()
        self._send_lock = threading.Lock()
        self._answers: dict[int, list[tuple[str, str | None]]] = {}
        threading.Thread(target=self._read_answers, name="recorder-answers", daemon=True).start()
        atexit.register(self.stop)

    def new_id(self) -> int:
        return next(self._ids)

    def alive(self) -> bool:
        return self.proc.poll() is None

    def send(self, request: tuple) -> None:
        data = pickle.dumps(request, protocol=pickle.HIGHEST_PROTOCOL)
        try:
            with self._send_lock:
                self.proc.stdin.write(_LEN.pack(len(data)) + data)
                self.proc.stdin.flush()
        except (OSError, ValueError) as exc:  # the recording process is gone
            raise OSError(f"the recording process ended ({exc})") from None

    def _read_answers(self) -> None:
        for kind, fid, msg in _frames(self.proc.stdout):
            with self._lock:
                self._answers.setdefault(fid, []).append((kind, msg))
                self._lock.notify_all()
        with self._lock:
            self._lock.notify_all()

    def answers(self, fid: int) -> list[tuple[str, str | None]]:
        with self._lock:
            return self._answers.pop(fid, [])

    def wait_done(self, fid: int, timeout_s: float) -> str | None:
        """The error finishing ``fid`` (None: finished), waiting for the recording process."""
        deadline = time.monotonic() + timeout_s
        with self._lock:
            while True:
                got = self._answers.get(fid, [])
                for kind, msg in got:
                    if kind == "done":
                        self._answers.pop(fid, None)
                        return msg
                left = deadline - time.monotonic()
                if left <= 0 or not self.alive():
                    return "the recording process did not answer"
                self._lock.wait(min(left, 0.5))

    def stop(self) -> None:
        if self.alive():
            with contextlib.suppress(OSError):
                self.send(("stop",))
            with contextlib.suppress(OSError):
                self.proc.stdin.close()
            try:
                self.proc.wait(timeout=FINISH_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                self.proc.terminate()


_PROCESS: _RecordingProcess | None = None
_PROCESS_LOCK = threading.Lock()


def recording_process() -> _RecordingProcess | None:
    """The recording process, started on first use; None where one cannot be started (a
    process cannot be started, or ``PEREGRINE_RECORD_IN_PROCESS=1``)."""
    global _PROCESS
    if os.environ.get("PEREGRINE_RECORD_IN_PROCESS") == "1":
        return None
    with _PROCESS_LOCK:
        if _PROCESS is not None and _PROCESS.alive():
            return _PROCESS
        try:
            _PROCESS = _RecordingProcess()
        except OSError:
            _PROCESS = None
        return _PROCESS


class ProcessSink:
    """Messages batched to the recording process; its failures come back as OSError."""

    def __init__(self, process: _RecordingProcess, path: Path) -> None:
        self.p = process
        self.fid = process.new_id()
        self._buf: list = []
        self._put = process.send
        self._put(("open", self.fid, str(path)))

    def _check(self) -> None:
        for kind, msg in self.p.answers(self.fid):
            if kind == "error":
                raise OSError(msg)
        if not self.p.alive():
            raise OSError("the recording process ended")

    def _flush(self) -> None:
        if self._buf:
            self._put(("msgs", self.fid, self._buf))
            self._buf = []
        self._check()

    def add(self, ti: int, ns: int, data: bytes) -> None:
        self._buf.append((ti, ns, RAW, data))
        if len(self._buf) >= BATCH:
            self._flush()

    def add_many(self, ns: int, items) -> None:
        """(channel index, encoder, payload) items: encoded in the recording process."""
        buf = self._buf
        for ti, enc, payload in items:
            buf.append((ti, ns, enc, payload))
        if len(buf) >= BATCH:
            self._flush()

    def metadata(self, name: str, data: dict[str, str]) -> None:
        self._flush()
        self._put(("meta", self.fid, name, data))

    def attachment(self, name: str, media_type: str, data: bytes) -> None:
        self._flush()
        self._put(("attach", self.fid, name, media_type, data))

    def started(self) -> None:
        self._flush()
        self._put(("flush", self.fid))

    def finish(self, outcome: dict[str, str]) -> None:
        if self._buf:
            self._put(("msgs", self.fid, self._buf))
            self._buf = []
        self._put(("finish", self.fid, outcome))
        err = self.p.wait_done(self.fid, FINISH_TIMEOUT_S)
        if err is not None:
            raise OSError(err)

    def abandon(self) -> None:
        self._buf = []


def open_sink(path: Path, fileobj, mode: str = "auto"):
    """``mode`` "auto": the recording process when one can run, else this process;
    "local": this process; "process": the recording process or an error."""
    if mode not in ("auto", "local", "process"):
        raise ValueError(f"unknown recording mode {mode!r}")
    proc = None if mode == "local" else recording_process()
    if proc is None:
        if mode == "process":
            raise OSError("no recording process can run here")
        return LocalSink(path, fileobj)
    fileobj.close()  # created here (exclusively); written there
    return ProcessSink(proc, path)


if __name__ == "__main__":  # the recording process
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is for the owner; we finish files
    answers = os.fdopen(os.dup(1), "wb")  # the answers' pipe; stray prints go to stderr
    os.dup2(2, 1)
    sys.stdout = sys.stderr
    _serve(sys.stdin.buffer, answers)
