"""Reading recorded sorties back: listing with a health status, summaries, time series and
index-based seeking. Damaged files are read up to the damage, never trusted past it.

Status of a file:
- ``ok``: summary present, every chunk's CRC checks;
- ``truncated``: the file stops early (a crash mid-sortie): readable up to the last chunk;
- ``damaged``: bytes inside are corrupt: readable up to the first bad record.
A file that is not MCAP at all is refused with :class:`LogError`.
"""

from __future__ import annotations

import json
import struct
import time
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from mcap.reader import make_reader
from mcap.records import Attachment, Channel, Message, Metadata
from mcap.stream_reader import StreamReader

MAGIC = b"\x89MCAP0\r\n"
SCENARIO_ATTACHMENT = "scenario.toml"  # the scenario flown, as the recorder attaches it
BEING_WRITTEN_S = 5.0  # a truncated file changed this recently is taken as being written


class LogError(ValueError):
    """Not a sortie log (not MCAP), or a name that would leave the log folder."""


@dataclass
class LogInfo:
    name: str
    size_bytes: int
    status: str  # ok | truncated | damaged
    problem: str | None
    scenario: str | None = None
    law: str | None = None
    seed: int | None = None
    camera: str | None = None
    outcome: str | None = None
    miss_m: float | None = None
    duration_s: float | None = None
    recorded_at_utc: str | None = None
    intercept_time_s: float | None = None
    reflown_from: str | None = None  # the recorded sortie this one re-flew
    messages: int = 0
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)

    def to_json_dict(self) -> dict[str, Any]:
        return asdict(self)


def _check_magic(path: Path) -> None:
    """Refuse, with what is wrong, a file that is not MCAP: nothing can be recovered from it."""
    with open(path, "rb") as f:
        head = f.read(len(MAGIC))
    if head == MAGIC:
        return
    if not head:
        raise LogError(f"{path.name}: not an MCAP file: empty (0 bytes), nothing to recover")
    if MAGIC.startswith(head):
        raise LogError(
            f"{path.name}: not an MCAP file: cut after {len(head)} bytes, inside the MCAP "
            "magic, nothing to recover"
        )
    raise LogError(
        f"{path.name}: not an MCAP file: it starts with {head[:8]!r}, not MCAP's magic "
        f"{MAGIC!r}; nothing to recover"
    )


def metadata_values(metadata: dict[str, dict[str, str]]) -> dict[str, dict[str, Any]]:
    """Metadata as values (MCAP stores strings; ours are JSON where they are not text):
    ``"0"`` -> 0, ``'{"k_a": 2.0}'`` -> a dict, ``"png"`` stays ``"png"``."""
    out: dict[str, dict[str, Any]] = {}
    for name, record in metadata.items():
        out[name] = {}
        for key, text in record.items():
            try:
                out[name][key] = json.loads(text)
            except ValueError:
                out[name][key] = text
    return out


def _apply_metadata(info: LogInfo, name: str, data: dict[str, str]) -> None:
    info.metadata[name] = dict(data)
    if name == "sortie":
        info.scenario = data.get("scenario")
        info.law = data.get("law")
        info.camera = data.get("camera")
        info.recorded_at_utc = data.get("recorded_at_utc")
        source = data.get("scenario_source", "")
        info.reflown_from = source if source.endswith(".mcap") else None
        try:
            info.seed = int(data.get("seed", ""))
        except ValueError:
            info.seed = None
    elif name == "outcome":
        out = {}
        for k, v in data.items():
            try:
                out[k] = json.loads(v)
            except ValueError:
                out[k] = v
        info.outcome = out.get("outcome")
        info.miss_m = out.get("miss_m")
        t = out.get("intercept_time_s")
        info.intercept_time_s = t if isinstance(t, (int, float)) else None


def _stream_scan(
    path: Path,
    info: LogInfo,
    topics: frozenset[str] = frozenset(),
    found: list[tuple[int, str, bytes]] | None = None,
    attachments: dict[str, bytes] | None = None,
    times: dict[str, list[int]] | None = None,
) -> bool:
    """Read every record in order with CRCs checked; stop at the first bad one. The messages
    on ``topics`` are kept in ``found`` as (log time ns, topic, data), the log times (ns) of
    those on the topics of ``times`` there, and the attachments in ``attachments``, from the
    same pass. Returns whether it stopped because the file ended early."""
    first = last = None
    ended_early = False
    channels: dict[int, str] = {}
    with open(path, "rb") as f:
        try:
            for rec in StreamReader(f, skip_magic=False, validate_crcs=True).records:
                if isinstance(rec, Message):
                    info.messages += 1
                    first = rec.log_time if first is None else min(first, rec.log_time)
                    last = rec.log_time if last is None else max(last, rec.log_time)
                    topic = channels.get(rec.channel_id)
                    if found is not None and topic in topics:
                        found.append((rec.log_time, topic, rec.data))
                    if times is not None and topic in times:
                        times[topic].append(rec.log_time)
                elif isinstance(rec, Channel):
                    channels[rec.id] = rec.topic
                elif isinstance(rec, Metadata):
                    _apply_metadata(info, rec.name, rec.metadata)
                elif isinstance(rec, Attachment) and attachments is not None:
                    attachments[rec.name] = rec.data
        except Exception as exc:  # mcap, zstd and lz4 each raise their own types
            # a cut inside a record's header surfaces as a short struct read: at the end of
            # the file that is the file ending early, not corrupt bytes
            ended_early = type(exc).__name__ in ("EndOfFile", "EOFError") or (
                isinstance(exc, struct.error) and f.tell() >= info.size_bytes
            )
            at = "its first message" if last is None else f"t = {last / 1e9:.2f} s"
            recovered = f"{info.messages} messages recovered"
            if ended_early:
                info.problem = f"truncated at {at}, {recovered}"
            else:
                why = f"{type(exc).__name__}: {exc}".rstrip(": ")
                info.problem = (
                    f"damaged near byte {f.tell()} of {info.size_bytes} ({why}): "
                    f"read up to {at}, {recovered}"
                )
    if first is not None:
        info.duration_s = (last - first) / 1e9
    return ended_early


@dataclass
class ReadLog:
    """One pass over a log (:func:`read_log`): its summary, the messages of the topics asked
    for (topic, time s, decoded JSON) in time order, and its attachments by name."""

    info: LogInfo
    messages: list[tuple[str, float, Any]]
    attachments: dict[str, bytes]
    times: dict[str, list[float]]  # the log times (s, sorted) of the topics asked for

    def attachment_text(self, name: str) -> str | None:
        data = self.attachments.get(name)
        return None if data is None else data.decode()


def inspect_log(path: Path) -> LogInfo:
    """Status and summary of one log (reads the whole file once, checking every CRC)."""
    return read_log(path).info


def read_log(
    path: Path, topics: list[str] | tuple[str, ...] = (), times_of: tuple[str, ...] = ()
) -> ReadLog:
    """Status and summary of one log, the messages on ``topics`` (decoded), the times of the
    messages on ``times_of`` (not decoded: camera frames) and the attachments, in one pass
    that checks every CRC (a damaged or truncated file is read up to the damage): what opening
    a sortie for replay needs, without reading the file a second time."""
    path = Path(path)
    _check_magic(path)
    info = LogInfo(name=path.name, size_bytes=path.stat().st_size, status="ok", problem=None)
    found: list[tuple[int, str, bytes]] = []
    attachments: dict[str, bytes] = {}
    times: dict[str, list[int]] = {t: [] for t in times_of}
    ended_early = _stream_scan(path, info, frozenset(topics), found, attachments, times)
    if info.problem is not None:
        info.status = "truncated" if ended_early else "damaged"
        if ended_early:
            age_s = time.time() - path.stat().st_mtime
            if age_s < BEING_WRITTEN_S:
                info.problem += f" so far: still being written ({age_s:.1f} s since its last write)"
            else:
                info.problem += " (the file ends early: a crash or a copy cut it)"
    found.sort(key=lambda m: m[0])  # stable: messages of one time keep the order written
    messages = [(topic, t / 1e9, json.loads(data)) for t, topic, data in found]
    return ReadLog(
        info, messages, attachments, {k: [t / 1e9 for t in sorted(v)] for k, v in times.items()}
    )


class LogIndex:
    """Listing of a log folder and its subfolders (a campaign's ``--log logs/NAME``); each
    file's inspection is cached by (size, mtime). A log's name is its path relative to the
    folder (``x.mcap``, ``static-n10/y.mcap``); nothing outside the folder is ever named."""

    MAX_DEPTH = 3  # subfolder levels listed

    def __init__(self, directory: Path) -> None:
        self.directory = Path(directory)
        self._cache: dict[str, tuple[tuple[int, int], LogInfo | str]] = {}

    def _inside(self, rel: str, what: str) -> Path:
        """``rel`` (``a/b``) under the folder, refusing anything that would leave it."""
        parts = rel.split("/") if rel else []
        if (
            "\\" in rel
            or "\x00" in rel
            or len(parts) > self.MAX_DEPTH + 1
            or any(not p or p.startswith(".") for p in parts)
        ):
            raise LogError(f"bad {what} {rel!r}")
        root = self.directory.resolve()
        path = (root / rel).resolve()
        if path != root and not path.is_relative_to(root):
            raise LogError(f"bad {what} {rel!r}")
        return path

    def resolve(self, name: str) -> Path:
        """The path of log ``name``, refusing anything that would leave the folder."""
        if not name:
            raise LogError(f"bad log name {name!r}")
        path = self._inside(name, "log name")
        if path.suffix != ".mcap":
            raise LogError(f"bad log name {name!r}")
        return path

    def folders(self) -> list[str]:
        """The folder ("") and its subfolders that hold recorded sorties, as relative names."""
        out: list[str] = []
        root = self.directory.resolve()
        if not root.is_dir():
            return out

        def walk(d: Path, depth: int) -> None:
            try:
                entries = sorted(d.iterdir())
            except OSError:
                return
            if any(e.suffix == ".mcap" and e.is_file() for e in entries) or d == root:
                out.append(d.relative_to(root).as_posix() if d != root else "")
            if depth < self.MAX_DEPTH:
                for e in entries:
                    if e.is_dir() and not e.name.startswith(".") and not e.is_symlink():
                        walk(e, depth + 1)

        walk(root, 0)
        return out

    def list(self, folder: str = "") -> list[dict[str, Any]]:
        """The sorties recorded in ``folder`` (relative to the log folder; "" itself)."""
        out = []
        d = self._inside(folder, "folder")
        if not d.is_dir():
            if folder:
                raise LogError(f"no folder {folder!r} in the log folder")
            return out
        prefix = f"{folder}/" if folder else ""
        for path in sorted(d.glob("*.mcap")):
            name = prefix + path.name
            try:
                st = path.stat()
            except OSError:  # deleted since the glob
                continue
            key = (st.st_size, st.st_mtime_ns)
            cached = self._cache.get(name)
            if cached is None or cached[0] != key:
                try:
                    value: LogInfo | str = inspect_log(path)
                except (LogError, OSError) as exc:  # one bad file never fails the listing
                    value = str(exc) if isinstance(exc, LogError) else f"{path.name}: {exc}"
                self._cache[name] = (key, value)
            value = self._cache[name][1]
            if isinstance(value, str):
                out.append(
                    {
                        "name": name,
                        "size_bytes": st.st_size,
                        "status": "not_mcap",
                        "problem": value,
                    }
                )
            else:
                d_ = value.to_json_dict()
                d_.pop("metadata")
                d_["name"] = name
                out.append(d_)
        return out

    def info(self, name: str) -> LogInfo:
        return inspect_log(self.resolve(name))


def iter_messages(
    path: Path,
    topics: list[str] | None = None,
    start_s: float | None = None,
    end_s: float | None = None,
) -> Iterator[tuple[str, float, dict]]:
    """(topic, time_s, decoded JSON) in time order. Uses the MCAP index (only the chunks that
    overlap [start_s, end_s] are read) when the file is whole; streams a damaged or truncated
    file from the start and stops at the damage."""
    path = Path(path)
    _check_magic(path)
    start_ns = None if start_s is None else int(start_s * 1e9)
    end_ns = None if end_s is None else int(end_s * 1e9)
    wanted = None if topics is None else set(topics)
    with open(path, "rb") as f:
        try:
            reader = make_reader(f)
            summary = reader.get_summary()
        except Exception:
            summary = None
        last_ns = None  # time of the last message yielded from the index
        if summary is not None and summary.chunk_indexes:
            try:
                window = {}
                if start_ns is not None:
                    window["starting_at"] = start_ns
                if end_ns is not None:
                    window["ending_before"] = end_ns
                for _schema, channel, msg in reader.iter_messages(topics=topics, **window):
                    last_ns = msg.log_time
                    yield channel.topic, msg.log_time / 1e9, json.loads(msg.data)
                return
            except Exception:  # a damaged chunk: stream on from there, up to the damage
                pass
        f.seek(0)
        channels: dict[int, str] = {}
        try:
            for rec in StreamReader(f, skip_magic=False, validate_crcs=True).records:
                if hasattr(rec, "topic") and hasattr(rec, "message_encoding"):
                    channels[rec.id] = rec.topic
                elif isinstance(rec, Message):
                    topic = channels.get(rec.channel_id)
                    if topic is None or (wanted is not None and topic not in wanted):
                        continue
                    if start_ns is not None and rec.log_time < start_ns:
                        continue
                    if last_ns is not None and rec.log_time <= last_ns:
                        continue
                    if end_ns is not None and rec.log_time >= end_ns:
                        continue
                    yield topic, rec.log_time / 1e9, json.loads(rec.data)
        except Exception:
            return  # the damage: everything before it has been yielded


def scenario_attachment(path: Path) -> str | None:
    _check_magic(path)
    with open(path, "rb") as f:
        try:
            for att in make_reader(f).iter_attachments():
                if att.name == SCENARIO_ATTACHMENT:
                    return att.data.decode()
        except Exception:
            return None
    return None


__all__ = [
    "LogError",
    "LogIndex",
    "LogInfo",
    "ReadLog",
    "inspect_log",
    "iter_messages",
    "metadata_values",
    "read_log",
    "scenario_attachment",
]
