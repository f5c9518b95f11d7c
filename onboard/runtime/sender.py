"""Work the control tick hands off: a thread runs what the tick submits, in order, after the
tick (``onboard run``'s telemetry to the ground, the log and STATUSTEXT of its events,
heartbeats and TIMESYNC requests). None of it feeds the command, so none of it has to delay
the tick: the tick takes a snapshot of what changes (references and numbers, no encoding) and
this thread builds and sends the messages.

Without :meth:`start` (``OnboardRuntime.tick`` called directly, as the tests do)
:meth:`submit` runs the work at once on the caller's thread.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable

_STOP = object()


class Sender(threading.Thread):
    """Runs submitted calls one at a time in submission order. An exception in one is counted
    in :attr:`errors` and passed to ``on_error``; the thread goes on."""

    def __init__(self, on_error: Callable[[str], None] | None = None) -> None:
        super().__init__(name="sender", daemon=True)
        self.errors = 0
        self._on_error = on_error
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._running = False
        self._held: list[tuple[Callable[..., object], tuple]] = []

    def start(self) -> None:
        self._running = True
        super().start()

    def submit(self, fn: Callable[..., object], *args: object) -> None:
        """Run ``fn(*args)`` on the thread (at once, here, when it is not running). Held until
        :meth:`flush`: the thread is not woken in the middle of a tick (a woken thread asks
        for the GIL, and the tick may have to hand it over)."""
        if self._running:
            self._held.append((fn, args))
        else:
            fn(*args)

    def flush(self) -> None:
        """Hand what was submitted since the last flush to the thread (after the tick)."""
        if self._held:
            held, self._held = self._held, []
            self._queue.put(held)

    def run(self) -> None:
        while True:
            batch = self._queue.get()
            if batch is _STOP:
                return
            for fn, args in batch:
                try:
                    fn(*args)
                except Exception as exc:
                    self.errors += 1
                    if self._on_error is not None:
                        self._on_error(f"sender: {type(exc).__name__}: {exc}")

    def stop(self, timeout_s: float = 2.0) -> None:
        """Run what is queued, then stop; later submissions run on the caller's thread."""
        if not self._running:
            return
        self.flush()
        self._queue.put(_STOP)
        self.join(timeout=timeout_s)
        self._running = False
