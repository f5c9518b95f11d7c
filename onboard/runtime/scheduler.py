"""When the control tick runs: fixed-rate ticks on absolute deadlines (k * period from the
start, so a late tick does not push the later ones back), reached by sleeping until a short
spin before the deadline and spinning the rest (the kernel's sleep overshoots by tens of
microseconds, more under load). Garbage collection never interrupts a tick: the heap built at
start-up is frozen out of the collector, automatic collection is off while the loop runs and
the young generations are collected in the slack after a tick. Optionally the control thread
(and the camera thread it starts afterwards) runs under SCHED_FIFO, as a flight stack's
threads do, so other programs on the companion computer cannot delay a tick.

The other Python threads (the links' receivers, the sender) hold the GIL while they work, and
a thread that has it keeps it for up to the switch interval: work of theirs that begins while
the control thread is spinning or ticking delays the tick by that much. They call
:meth:`PeriodicScheduler.wait_for_slack` before each piece of work, which returns at once while
the control thread sleeps and otherwise waits, without the GIL, until its tick is done.
"""

from __future__ import annotations

import gc
import os
import sys
import threading
import time

SPIN_S = 0.0003  # the last 0.3 ms before a deadline are spun, not slept
GC_YOUNG_EVERY_S = 0.5  # collect generation 0 this often, in a tick's slack
GC_OLDER_EVERY_S = 10.0  # and generation 1 this often
GC_MIN_SLACK_S = 0.002  # only when this much time is left before the next deadline
MAX_HOLD_OFF_S = 1.0  # wait_for_slack never holds another thread longer than this
SLACK_LEAD_S = 0.0002  # nor lets one start work this close to the control thread's wake-up


class PeriodicScheduler:
    """Call :meth:`start` once on the control thread, then per tick :meth:`wait` (returns the
    tick's start time, perf_counter seconds), run the tick, :meth:`after_tick`; :meth:`stop`
    at the end restores the interpreter's defaults."""

    def __init__(
        self, period_s: float, spin_s: float = SPIN_S, realtime_priority: int | None = None
    ) -> None:
        if not period_s > 0.0:
            raise ValueError("period_s must be positive")
        self.period_s = period_s
        self.spin_s = min(max(spin_s, 0.0), period_s)
        self.realtime_priority = realtime_priority
        self.stalls = 0  # times the loop fell a whole period behind and re-anchored
        self.gc_runs = 0
        self._next_s = 0.0
        self._next_young_s = self._next_older_s = 0.0
        self._switch_interval = sys.getswitchinterval()
        self._gc_was_enabled = gc.isenabled()
        self._running = False
        self._busy = False  # the control thread is awake: spinning to a deadline or ticking
        self._done = threading.Condition(threading.Lock())
        self._ticks_done = 0

    def start(self) -> str | None:
        """Freeze the start-up heap, take collection into our hands, let this thread take the
        GIL promptly and, if asked, switch it to SCHED_FIFO. Returns a note on what could not
        be done (no permission for real-time priority), else None."""
        note = None
        if self.realtime_priority is not None:
            try:
                os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(self.realtime_priority))
            except (AttributeError, OSError, ValueError) as exc:
                note = f"real-time priority {self.realtime_priority} refused ({exc}): normal"
        sys.setswitchinterval(0.0005)
        gc.collect()
        gc.freeze()
        gc.disable()
        now = time.perf_counter()
        self._next_s = now
        self._next_young_s = now + GC_YOUNG_EVERY_S
        self._next_older_s = now + GC_OLDER_EVERY_S
        self._running = True
        return note

    def wait(self) -> float:
        """Return at the next deadline (sleeping, then spinning); when a stall left the loop
        more than a period behind, start afresh from now rather than run a burst of ticks."""
        deadline = self._next_s
        now = time.perf_counter()
        if now > deadline + self.period_s:
            self.stalls += 1
            deadline = now
            self._busy = True
        else:
            if deadline - now > self.spin_s:
                time.sleep(deadline - now - self.spin_s)
            self._busy = True
            while time.perf_counter() < deadline:
                pass
        self._next_s = deadline + self.period_s
        return time.perf_counter()

    def after_tick(self) -> None:
        """Let the threads waiting for slack go; collect garbage if due and there is slack
        before the next deadline."""
        self._tick_over()
        now = time.perf_counter()
        if now < self._next_young_s or self._next_s - now < GC_MIN_SLACK_S:
            return
        self._next_young_s = now + GC_YOUNG_EVERY_S
        if now >= self._next_older_s:
            self._next_older_s = now + GC_OLDER_EVERY_S
            gc.collect(1)
        else:
            gc.collect(0)
        self.gc_runs += 1

    def _tick_over(self) -> None:
        with self._done:
            self._busy = False
            self._ticks_done += 1
            self._done.notify_all()

    def wait_for_slack(self) -> None:
        """For the other threads, before a piece of work: return at once while the control
        thread sleeps with more than ``SLACK_LEAD_S`` to go before it wakes (``spin_s`` before
        its deadline); otherwise when its tick is over. Their work then falls in the tick's
        slack, not at its start: under SCHED_FIFO a thread of the same priority is not
        preempted, so work begun just before the wake-up would delay the tick by its length."""
        if not self._running:
            return
        if not self._busy and self._next_s - self.spin_s - time.perf_counter() >= SLACK_LEAD_S:
            return
        with self._done:
            n = self._ticks_done
            self._done.wait_for(
                lambda: self._ticks_done != n or not self._running,
                timeout=MAX_HOLD_OFF_S,
            )

    def stop(self) -> None:
        """Hand collection back to the interpreter (and let any waiting thread go)."""
        self._running = False
        self._tick_over()
        gc.unfreeze()
        if self._gc_was_enabled:
            gc.enable()
        sys.setswitchinterval(self._switch_interval)
