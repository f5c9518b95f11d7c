"""The flight controller's messages received and parsed off the control thread: a thread waits
on the link's socket (without holding the GIL), parses what arrives with the link's own
:meth:`~onboard.link.px4.MavLink.poll` and queues the messages; the control tick only drains
the queue. PX4 streams about 500 messages a second at the rates the loop asks for, and parsing
them inside the tick was most of its work beyond the loop itself.

Only the receive side runs here: sending stays on the control thread. The flight-controller
link is unsigned, so the two sides share no state of the parser; the ground link (signed, a
few messages a second) keeps being polled by the tick.
"""

from __future__ import annotations

import collections
import select
import threading
import time

from ..link.px4 import MavLink

WAIT_S = 0.05  # longest wait on the socket before checking for stop


class LinkReceiver(threading.Thread):
    """Parses ``link``'s input into a queue; :meth:`drain` takes everything queued."""

    def __init__(self, link: MavLink) -> None:
        super().__init__(name=f"rx {link.url}", daemon=True)
        self.link = link
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
            if msgs:
                self._queue.extend(msgs)

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
