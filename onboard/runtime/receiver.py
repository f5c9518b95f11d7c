"""The links' messages received and parsed off the control thread: a thread waits on the
link's socket (without holding the GIL), parses what arrives with the link's own
:meth:`~onboard.link.px4.MavLink.poll` and either queues the messages for the control tick to
drain or hands each batch to ``on_messages`` right away (``onboard run`` takes PX4's state in
there, under the loop's lock, so the tick only reads it). PX4 streams about 500 messages a
second at the rates the loop asks for; parsing and converting them inside the tick would be
most of its work beyond the loop itself.
"""

from __future__ import annotations

import collections
import select
import threading
import time
from collections.abc import Callable

from ..link.px4 import MavLink

WAIT_S = 0.05  # longest wait on the socket before checking for stop


class LinkReceiver(threading.Thread):
    """Parses ``link``'s input into a queue (:meth:`drain` takes everything queued) or, with
    ``on_messages``, hands each batch to it on this thread (an exception it raises is counted
    in :attr:`errors` and passed to ``on_error``; the thread goes on)."""

    def __init__(
        self,
        link: MavLink,
        on_messages: Callable[[list], None] | None = None,
        on_error: Callable[[str], None] | None = None,
    ) -> None:
        super().__init__(name=f"rx {link.url}", daemon=True)
        self.link = link
        self.errors = 0
        self._on_messages = on_messages
        self._on_error = on_error
        self._queue: collections.deque = collections.deque()
        self._stop_event = threading.Event()
        port = getattr(link.conn, "port", None)
        self._waitable = port if port is not None and hasattr(port, "fileno") else None

    def run(self) -> None:
        while not self._stop_event.is_set():
            if self._waitable is not None:
                try:
                    ready, _, _ = select.select([self._waitable], [], [], WAIT_S)
                except (OSError, ValueError):  # the link was closed under us
                    return
                if not ready:
                    continue
            else:  # a source with nothing to wait on: poll at 1 kHz
                time.sleep(0.001)
            msgs = self.link.poll()
            if not msgs:
                continue
            if self._on_messages is None:
                self._queue.extend(msgs)
                continue
            try:
                self._on_messages(msgs)
            except Exception as exc:  # a handler's bug must not stop PX4's state coming in
                self.errors += 1
                if self._on_error is not None:
                    self._on_error(f"receiver: {type(exc).__name__}: {exc}")

    def drain(self) -> list:
        """Every message parsed since the last call, oldest first."""
        q, out = self._queue, []
        while q:
            out.append(q.popleft())
        return out

    def stop(self) -> None:
        self._stop_event.set()
        if self.is_alive():
            self.join(timeout=2.0 * WAIT_S + 0.5)
