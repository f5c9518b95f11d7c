"""MAVLink telemetry logs (``.tlog``) of every frame a link sends and receives."""

from __future__ import annotations

import contextlib
import time
from pathlib import Path


class TlogWriter:
    """A MAVLink telemetry log (``.tlog``: per frame an 8-byte big-endian UNIX time in
    microseconds, then the frame as sent or received), the format QGroundControl, MAVProxy
    and pymavlink read. A new file per run, never an existing one; a write error (a full
    disk) closes it and is reported through :attr:`error`, it never stops the caller."""

    def __init__(self, path) -> None:
        self.path = path
        self._f = open(path, "xb")  # noqa: SIM115 - kept open for the whole run
        self.error: str | None = None

    def write(self, frame: bytes) -> None:
        if self._f is None:
            return
        try:
            self._f.write(int(time.time() * 1e6).to_bytes(8, "big") + bytes(frame))
        except (OSError, ValueError) as exc:
            self.error = f"tlog {self.path}: {exc}"
            self.close()

    def close(self) -> None:
        if self._f is not None:
            with contextlib.suppress(OSError):
                self._f.close()
            self._f = None

    @classmethod
    def new_in(cls, log_dir: Path, name: str) -> TlogWriter:
        """A new ``<UTC>_<name>[_n].tlog`` in ``log_dir`` (created if needed)."""
        log_dir.mkdir(parents=True, exist_ok=True)
        stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime())
        path, n = log_dir / f"{stamp}_{name}.tlog", 1
        while path.exists():
            n += 1
            path = log_dir / f"{stamp}_{name}_{n}.tlog"
        return cls(path)
