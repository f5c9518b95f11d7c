"""When the control tick runs: a fixed rate on absolute deadlines. Deadline k is
``t0 + k * period`` on the monotonic clock, slept to with ``clock_nanosleep(TIMER_ABSTIME)``
(the kernel wakes the thread at the deadline however long the previous tick took). A tick that
wakes a period or more after its deadline is counted as late and the next deadline is the next
multiple of the period after it: the deadlines it missed are dropped, never run as a burst.

Garbage collection never interrupts a tick: the heap built at start-up is frozen out of the
collector, automatic collection is off while the loop runs and the young generations are
collected after a tick when enough of the period is left.

Timing itself comes from the operating system (:mod:`.realtime`: SCHED_FIFO, locked memory,
an isolated CPU); this module only keeps the grid.
"""

from __future__ import annotations

import gc
import math
import time
from collections import deque
from collections.abc import Callable

from .faults import WakeDelays

GC_YOUNG_EVERY_S = 0.5  # collect generation 0 this often, after a tick
GC_OLDER_EVERY_S = 10.0  # and generation 1 this often
GC_MIN_SLACK_S = 0.002  # only when this much time is left before the next deadline


def _libc_sleep_until() -> Callable[[float], None] | None:
    """``clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME)`` from libc (Linux), or None."""
    try:
        import ctypes
        import ctypes.util
        import os

        if not hasattr(time, "CLOCK_MONOTONIC") or os.name != "posix":
            return None
        libc = ctypes.CDLL(ctypes.util.find_library("c") or None, use_errno=True)
        nanosleep = libc.clock_nanosleep
    except (OSError, AttributeError):
        return None

    class Timespec(ctypes.Structure):
        _fields_ = [("tv_sec", ctypes.c_long), ("tv_nsec", ctypes.c_long)]

    nanosleep.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.POINTER(Timespec), ctypes.c_void_p]
    clock_id, timer_abstime, eintr = time.CLOCK_MONOTONIC, 1, 4

    def sleep_until(deadline_s: float) -> None:
        sec = math.floor(deadline_s)
        ts = Timespec(sec, int((deadline_s - sec) * 1e9))
        while nanosleep(clock_id, timer_abstime, ctypes.byref(ts), None) == eintr:
            pass  # a signal: sleep on to the same deadline (ctypes releases the GIL)

    return sleep_until


def _plain_sleep_until(deadline_s: float) -> None:
    """Where libc's absolute sleep is not available: sleep the time left."""
    left = deadline_s - time.monotonic()
    if left > 0.0:
        time.sleep(left)


def default_sleep_until() -> Callable[[float], None]:
    """Sleep to an absolute ``time.monotonic()`` deadline: libc's ``clock_nanosleep`` where
    there is one, else ``time.sleep`` of the time left."""
    return _libc_sleep_until() or _plain_sleep_until


class PeriodicScheduler:
    """Call :meth:`start` once on the control thread, then per tick :meth:`wait` (returns the
    tick's start, monotonic seconds), run the tick, :meth:`after_tick`; :meth:`stop` at the end
    gives garbage collection back to the interpreter. ``clock`` and ``sleep_until`` (sleep to
    an absolute time of ``clock``) are for tests with a fake clock; ``delays`` delays each
    wake-up (fault injection, :mod:`.faults`)."""

    def __init__(
        self,
        period_s: float,
        clock: Callable[[], float] = time.monotonic,
        sleep_until: Callable[[float], None] | None = None,
        delays: WakeDelays | None = None,
    ) -> None:
        if not (math.isfinite(period_s) and period_s > 0.0):
            raise ValueError("period_s must be a positive number of seconds")
        self.period_s = period_s
        self._clock = clock
        if sleep_until is None:
            if clock is not time.monotonic:
                raise ValueError("a clock of its own needs a sleep_until of its own")
            sleep_until = default_sleep_until()
        self._sleep_until = sleep_until
        self.delays = delays
        self.late_ticks = 0  # ticks woken a period or more after their deadline
        self.missed_deadlines = 0  # the deadlines those dropped
        self.injected_s = 0.0  # the wake-up delays injected, summed
        self.gc_runs = 0
        self._late: deque[float] = deque(maxlen=max(round(1.0 / period_s), 1))
        self._late_sum = 0.0
        self._t0 = 0.0
        self._next_s = 0.0
        self._next_young_s = self._next_older_s = 0.0
        self._gc_was_enabled = gc.isenabled()
        self._running = False

    def start(self) -> None:
        """Freeze the start-up heap and take collection into our hands; the first deadline is
        now."""
        gc.collect()
        gc.freeze()
        gc.disable()
        now = self._clock()
        self._t0 = self._next_s = now
        self._next_young_s = now + GC_YOUNG_EVERY_S
        self._next_older_s = now + GC_OLDER_EVERY_S
        self._running = True

    @property
    def next_deadline_s(self) -> float:
        """The next tick's deadline (monotonic s)."""
        return self._next_s

    def wait(self) -> float:
        """Sleep to the next deadline and return the tick's start (s). A tick starting a
        period or more after its deadline is counted late; the next deadline is then the next
        multiple of the period after the start."""
        deadline = self._next_s
        self._sleep_until(deadline)
        if self.delays is not None:
            extra = self.delays.next_s(deadline - self._t0)
            if extra > 0.0:
                self.injected_s += extra
                self._sleep_until(self._clock() + extra)
        start = self._clock()
        period = self.period_s
        missed = max(math.floor((start - deadline) / period), 0)
        nxt = deadline + (missed + 1) * period
        while nxt <= start:  # rounding: the next deadline is after the start
            nxt += period
            missed += 1
        if missed:
            self.late_ticks += 1
            self.missed_deadlines += missed
        self._next_s = nxt
        late = min(start - deadline, period)
        if len(self._late) == self._late.maxlen:
            self._late_sum -= self._late[0]
        self._late.append(late)
        self._late_sum += late
        return start

    def hold_s(self, start_s: float) -> float:
        """How long a command sent by the tick that started at ``start_s`` is expected to be
        held (s): until the next tick, i.e. the next deadline plus how late the wake-ups have
        been of late (their mean over the last second, each counted up to a period: a stall's
        excess is the loop's to take back when the tick after it comes)."""
        return max(self._next_s - start_s, 0.0) + self._late_sum / max(len(self._late), 1)

    def after_tick(self) -> None:
        """Collect young garbage if it is due and enough of the period is left."""
        now = self._clock()
        if now < self._next_young_s or self._next_s - now < GC_MIN_SLACK_S:
            return
        self._next_young_s = now + GC_YOUNG_EVERY_S
        if now >= self._next_older_s:
            self._next_older_s = now + GC_OLDER_EVERY_S
            gc.collect(1)
        else:
            gc.collect(0)
        self.gc_runs += 1

    def figures(self) -> dict:
        """Late ticks, the deadlines they dropped, the injected delays, the collections."""
        d = self.delays
        return {
            "late_ticks": self.late_ticks,
            "missed_deadlines": self.missed_deadlines,
            "injected_delay_s": self.injected_s,
            "injected_stalls": None if d is None else d.stalls,
            "injected_freezes": None if d is None else d.freezes,
            "gc_runs_after_ticks": self.gc_runs,
        }

    def stop(self) -> None:
        """Hand collection back to the interpreter."""
        if not self._running:
            return
        self._running = False
        gc.unfreeze()
        if self._gc_was_enabled:
            gc.enable()
