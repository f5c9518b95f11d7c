"""Writes one sortie to ``logs/<UTC time>_<scenario>_<law>.mcap`` while it flies.

:class:`SortieRecorder` is a sortie observer (:mod:`onboard.frames`): whoever produces
the sortie (the simulator, live mode) tells it ``start``, each ``frame`` and ``image``, and
``finish``; it reads nothing else. Its messages are the channels' one definition
(:class:`~onboard.channels.builder.ChannelBuilder`, which it is); this module opens the file.

Chunked and indexed MCAP (zstd), JSON messages with Foxglove's well-known schemas, log times
on the sortie's own clock. The file is created here, exclusively (an existing one is never
overwritten); the sortie's thread gathers each message's numbers and hands them, in batches,
to the recording process (:mod:`.sink`), which encodes (:mod:`onboard.channels.encode`) and
writes them, each full chunk reaching disk as it is written. If the sortie's process dies,
the recording process still writes what it was sent and finishes the file (outcome
INCOMPLETE); where no recording process can run, the same code writes in this process and a
crash leaves a file readable up to its last chunk. A write error (a full disk) ends the
recording with a clear message in ``error`` and never the sortie.
:meth:`SortieRecorder.finish` returns once the file is complete. Rates: see
:mod:`onboard.channels.builder`.
"""

from __future__ import annotations

import re
from datetime import datetime, timezone
from pathlib import Path

from onboard import __version__ as onboard_version
from onboard.channels.builder import ChannelBuilder
from onboard.frames import SortieStart

from .. import __version__ as gs_version
from .sink import open_sink


def log_name(scenario: str, law: str, when: datetime | None = None) -> str:
    when = when or datetime.now(timezone.utc)
    safe = re.sub(r"[^A-Za-z0-9_.-]+", "-", scenario).strip("-") or "sortie"
    return f"{when:%Y%m%dT%H%M%SZ}_{safe}_{law}.mcap"


def open_new_log(directory: Path, scenario: str, law: str):
    """Create a new log file exclusively; a clash gets a -2, -3 ... suffix, never overwrite."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    base = log_name(scenario, law)
    for k in range(1, 1000):
        name = base if k == 1 else base.replace(".mcap", f"-{k}.mcap")
        try:
            return directory / name, open(directory / name, "xb")
        except FileExistsError:
            continue
    raise FileExistsError(f"no free log name for {base} in {directory}")


class SortieRecorder(ChannelBuilder):
    """Records the sortie it observes into a new file in ``directory`` (created at
    :meth:`start`; ``path`` is None before)."""

    def __init__(
        self,
        directory: Path | None,
        record_every: int = 5,
        annotate_every: int = 3,
        frame_every: int = 6,
        mode: str = "auto",
        sink=None,
    ) -> None:
        """``sink``: where the messages go instead of a new file in ``directory``."""
        super().__init__(sink, record_every, annotate_every, frame_every)
        self.directory = None if directory is None else Path(directory)
        self.mode = mode

    software = f"peregrine {gs_version} (onboard {onboard_version})"

    def _open_sink(self, info: SortieStart):
        """Create the file and its sink (None, with ``error`` set, when that fails)."""
        if self._given_sink is not None:
            return self._given_sink
        try:  # the log folder may have become unusable since the server started
            self.path, fileobj = open_new_log(self.directory, info.scenario, info.law)
        except OSError as exc:
            self.error = (
                f"cannot create a log file in {self.directory}: {type(exc).__name__}: {exc}"
            )
            self.closed = True
            return None
        try:
            return open_sink(self.path, fileobj, self.mode)
        except OSError as exc:
            fileobj.close()
            self._fail(exc)
            return None
