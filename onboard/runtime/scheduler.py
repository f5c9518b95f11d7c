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

CPU placement (``onboard run --reserve-cpu``, on by default): one CPU (the highest-numbered
the process may use) is left to the control thread: every other thread of the process (the
links' receivers, the sender, the camera thread, the video and Foxglove threads, the libraries'
own) is kept off it, and the control thread is bound to it. A thread woken on the control
thread's CPU (a PX4 datagram arriving, a frame detected) would otherwise preempt a tick: traced
on a 2-core machine, such wake-ups were most of the tick-work tail beyond its CPU time; and an
unbound control thread ran nearly always on the other CPU, with those threads (README "CPU
placement"). Bound, it cannot leave its CPU when another program runs there (it once waited
5.7 ms behind one while the other CPU was free), so :class:`BindingWatch` frees it while it
waits there for more than 5 % of the time, for ten seconds at a time (longer while the other
program stays); without the run delay to watch by (no /proc schedstat) it is not bound. Not
under SCHED_FIFO (``--realtime``): there a woken thread of the same priority does not preempt
a running one, and the others would only be crowded onto fewer CPUs. :func:`split_cpus`
chooses, :func:`keep_off` applies.

Rehearsal (``rehearse``, :mod:`.rehearsal`): the control thread wakes ``rehearse_lead_s``
earlier still and calls ``rehearse`` (the tick's expensive part on a copy, so the tick finds its
code and data in the caches), then spins to the deadline as before. Not before an early tick or
while an input is being handed over; the other threads are held off it as off the spin.

Early ticks: another thread with a new input for the tick (the camera thread, right after it
fused a detection) calls :meth:`PeriodicScheduler.request_tick`; the control thread, asleep or
spinning, then ticks at once instead of at the next deadline (never sooner than
``min_gap_s`` after the previous tick's start) and the grid re-anchors one period after that
tick, so the early tick's command is held a whole period and no grid tick follows it closely.
A request the tick has already taken in is withdrawn with :meth:`PeriodicScheduler.served`
(called under the lock the requester holds while it hands the input over): one input, one
tick. While the control thread sleeps, the requester ticks the early tick itself instead
(:meth:`PeriodicScheduler.tick_here`, right after the fusion, under the same lock): the fused
state is in its CPU's caches and no thread is woken across CPUs (README "Session 17": the
early ticks' share of the slowest 1 % of ticks about halved). A tick falling due while an
input is being handed over (:meth:`input_begins` .. :meth:`input_done`, the fusion under the
loop's lock) waits for it asleep, at most half a period, and starts when it is in,
re-anchored there.
"""

from __future__ import annotations

import gc
import math
import os
import sys
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable

from .timing import EARLY_TICK, ON_THE_GRID

# how a tick's wake-up went (PeriodicScheduler.woken_as), besides early and on the grid
REHEARSED = "rehearsed"  # the rehearsal ran before it
FUSION = "fusion"  # not rehearsed: a fusion was running at the wake-up
WOKEN_LATE = "woken late"  # not rehearsed: woken too close to the deadline
DECLINED = "declined"  # not rehearsed: ``rehearse`` returned False (nothing to rehearse on)
STALL = "stall"  # the loop fell a period behind and started afresh

SPIN_S = 0.0003  # the last 0.3 ms before a deadline are spun, not slept
GC_YOUNG_EVERY_S = 0.5  # collect generation 0 this often, in a tick's slack
GC_OLDER_EVERY_S = 10.0  # and generation 1 this often
GC_MIN_SLACK_S = 0.002  # only when this much time is left before the next deadline
MAX_HOLD_OFF_S = 1.0  # wait_for_slack never holds another thread longer than this
SLACK_LEAD_S = 0.0002  # nor lets one start work this close to the control thread's wake-up
MIN_GAP_FRACTION = 0.2  # an early tick starts no sooner than this many periods after the last
MAX_INPUT_WAIT_FRACTION = 0.5  # a due tick waits at most this many periods for an input
# the control thread bound to the CPU left to it, unless it waits there (BindingWatch): looked
# at every half second; more than 5 % of it waiting for the CPU (another program there) frees
# it for ten seconds, then it is bound again (freed at once again: twice as long, up to 160 s)
BINDING_CHECK_EVERY_S = 0.5
BINDING_MAX_WAIT_FRACTION = 0.05
BINDING_UNBOUND_FOR_S = 10.0
BINDING_UNBOUND_MAX_S = 160.0
REHEARSALS_KEPT = 120_000  # the last ten minutes' rehearsal times at 200 Hz


_PR_SET_TIMERSLACK, _PR_GET_TIMERSLACK = 29, 30  # prctl(2)


def set_timer_slack_ns(ns: int) -> int | None:
    """Set this thread's timer slack (Linux: how much later than asked the kernel may end its
    sleeps, to group wake-ups; 50 us by default) and return the previous value, or None where
    it cannot be set (not Linux, no libc)."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        import ctypes

        prctl = ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):
        return None
    zero = ctypes.c_ulong(0)
    before = prctl(_PR_GET_TIMERSLACK, zero, zero, zero, zero)
    if before < 0 or prctl(_PR_SET_TIMERSLACK, ctypes.c_ulong(ns), zero, zero, zero) != 0:
        return None
    return before


def run_delay_s() -> float | None:
    """How long this thread has waited, runnable, for a CPU since it began (s; Linux's
    /proc/thread-self/schedstat), or None where that is not available."""
    try:
        with open("/proc/thread-self/schedstat", "rb") as f:
            return int(f.read().split()[1]) * 1e-9
    except (OSError, ValueError, IndexError):
        return None


class BindingWatch:
    """Whether the control thread should stay bound to the CPU left to it (pure logic; the
    runtime reads the clock and the run delay, applies the answer and says so with
    :meth:`applied`). Bound, a thread cannot leave its CPU when another program runs there: so
    every ``check_every_s`` it looks at how long the thread waited for that CPU, and when that
    was more than ``max_wait_fraction`` of the time it frees it (free to run on any CPU, as the
    system puts it) for ``unbound_for_s``, then binds it again and looks afresh. Freed again in
    the first look after being bound again (the program is still there), it stays free twice
    as long each time, up to ``unbound_max_s``; a look that finds it waiting no more than that
    brings the time back to ``unbound_for_s``."""

    def __init__(
        self,
        check_every_s: float = BINDING_CHECK_EVERY_S,
        max_wait_fraction: float = BINDING_MAX_WAIT_FRACTION,
        unbound_for_s: float = BINDING_UNBOUND_FOR_S,
        unbound_max_s: float = BINDING_UNBOUND_MAX_S,
    ) -> None:
        self.check_every_s = check_every_s
        self.max_wait_fraction = max_wait_fraction
        self.unbound_base_s = unbound_for_s
        self.unbound_max_s = max(unbound_max_s, unbound_for_s)
        self.unbound_for_s = unbound_for_s  # the next freeing's
        self.bound = True
        self.escapes = 0  # times freed
        self.last_wait_fraction = 0.0  # of the last look, bound
        self.max_wait_fraction_seen = 0.0
        self._since_s: float | None = None  # the look's window start (or the freeing)
        self._delay_at_start_s = 0.0
        self._just_bound = False  # no look since it was bound again

    def due(self, now_s: float) -> bool:
        """Whether :meth:`step` has something to do at ``now_s`` (s)."""
        if self._since_s is None:
            return True
        limit = self.check_every_s if self.bound else self.unbound_for_s
        return now_s - self._since_s >= limit

    def step(self, now_s: float, run_delay_s: float) -> bool | None:
        """At ``now_s`` (s) with the thread's total ``run_delay_s`` (s): True to bind it
        again, False to free it, None to leave it as it is. A change is the runtime's to
        apply; it calls :meth:`applied` once it has."""
        if self._since_s is None:
            self._since_s, self._delay_at_start_s = now_s, run_delay_s
            return None
        if not self.due(now_s):
            return None
        if not self.bound:
            return True
        fraction = (run_delay_s - self._delay_at_start_s) / (now_s - self._since_s)
        self.last_wait_fraction = fraction
        self.max_wait_fraction_seen = max(self.max_wait_fraction_seen, fraction)
        self._since_s, self._delay_at_start_s = now_s, run_delay_s
        if fraction > self.max_wait_fraction:
            return False
        self._just_bound = False
        self.unbound_for_s = self.unbound_base_s
        return None

    def applied(self, bound: bool, now_s: float, run_delay_s: float) -> None:
        """The runtime bound (True) or freed (False) the thread at ``now_s`` (s), its total
        run delay then ``run_delay_s`` (s)."""
        if not bound:
            self.escapes += 1
            if self._just_bound:  # still there: free for longer
                self.unbound_for_s = min(2.0 * self.unbound_for_s, self.unbound_max_s)
        self.bound = bound
        self._just_bound = bound
        self._since_s, self._delay_at_start_s = now_s, run_delay_s


def split_cpus(cpus: Iterable[int]) -> tuple[set[int], set[int]] | None:
    """(the CPU left to the control thread, the other threads' CPUs) from the CPUs the
    process may use: the highest-numbered, and the rest; None with fewer than two (nothing to
    split)."""
    ordered = sorted(set(cpus))
    if len(ordered) < 2:
        return None
    return {ordered[-1]}, set(ordered[:-1])


def keep_off(cpus: set[int], except_thread_id: int) -> str | None:
    """Put every thread of this process but the one with native id ``except_thread_id`` on
    ``cpus`` (Linux: its threads are listed in /proc/self/task; a thread that ended meanwhile
    is skipped). Returns a note when that cannot be done (no /proc, no ``sched_setaffinity``,
    a CPU set refused), else None; threads moved before a refusal stay moved (the caller puts
    them back)."""
    try:
        tids = [int(name) for name in os.listdir("/proc/self/task")]
        for tid in tids:
            if tid == except_thread_id:
                continue
            try:
                os.sched_setaffinity(tid, cpus)
            except ProcessLookupError:
                continue  # ended since the listing
    except (AttributeError, OSError, ValueError) as exc:
        return f"CPU placement refused ({exc}): threads left where the system puts them"
    return None


class PeriodicScheduler:
    """Call :meth:`start` once on the control thread, then per tick :meth:`wait` (returns the
    tick's start time, perf_counter seconds; :attr:`early` says whether a request brought it
    forward), run the tick, :meth:`after_tick`; :meth:`stop` at the end restores the
    interpreter's defaults. ``clock`` and ``block`` (sleep up to the given seconds, returning
    sooner if :meth:`request_tick` is called) are for tests with a fake clock."""

    def __init__(
        self,
        period_s: float,
        spin_s: float = SPIN_S,
        realtime_priority: int | None = None,
        min_gap_s: float | None = None,
        clock: Callable[[], float] = time.perf_counter,
        block: Callable[[float], None] | None = None,
        rehearse: Callable[[], bool] | None = None,
        rehearse_lead_s: float = 0.0,
    ) -> None:
        if not period_s > 0.0:
            raise ValueError("period_s must be positive")
        self.period_s = period_s
        self.spin_s = min(max(spin_s, 0.0), period_s)
        gap = MIN_GAP_FRACTION * period_s if min_gap_s is None else min_gap_s
        self.min_gap_s = min(max(gap, 0.0), period_s)
        self.realtime_priority = realtime_priority
        # rehearsal.py: woken rehearse_lead_s before the spin to run ``rehearse``
        self.rehearse = rehearse
        self.rehearse_lead_s = 0.0 if rehearse is None else min(max(rehearse_lead_s, 0.0), period_s)
        self.rehearsal_s: deque[float] = deque(maxlen=REHEARSALS_KEPT)  # how long each took
        # how late the sleep before a grid tick ended after the time asked (the kernel's, the
        # hypervisor's and the GIL's delay): later than the lead leaves no time to rehearse
        self.wake_overshoot_s: deque[float] = deque(maxlen=REHEARSALS_KEPT)
        # wake-ups not rehearsed: for an early tick, during a fusion, too late
        self.rehearsals_skipped = dict.fromkeys((EARLY_TICK, FUSION, WOKEN_LATE, DECLINED), 0)
        self.stalls = 0  # times the loop fell a whole period behind and re-anchored
        self.early_ticks = 0  # ticks brought forward by request_tick or tick_here
        self.ticks_here = 0  # of which the requesting thread ticked itself (tick_here)
        self.early = False  # the tick wait() last returned was brought forward
        self.woken_as = ON_THE_GRID  # how its wake-up went: REHEARSED, EARLY_TICK, ...
        self.gc_runs = 0
        self._clock = clock
        self._block = block or self._block_until_request
        self._block_saw_request = False  # whether the timeout given to _block counted a request
        self._next_s = 0.0
        self._last_start_s = -math.inf
        self._requested = False  # request_tick() since the last served()
        self._inputting = False  # input_begins() without input_done(): a fusion running
        self._awaiting_input = False  # wait() is blocked until it is done
        self.input_waits = 0  # due ticks that waited for a running fusion to end
        self.input_wait_max_s = 0.0
        self._wake = threading.Condition(threading.Lock())
        self._next_young_s = self._next_older_s = 0.0
        self._switch_interval = sys.getswitchinterval()
        self._gc_was_enabled = gc.isenabled()
        self._timer_slack_was: int | None = None  # the control thread's, before start()
        self._running = False
        self._busy = False  # the control thread is awake (spinning to a deadline or ticking)
        self._ticking_here = False  # or another thread ticks (tick_here)
        self._collecting = False  # after_tick collects garbage: no tick_here meanwhile
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
        # sleeps end when asked, not up to 50 us later: the wake-up is 0.6 ms before the
        # deadline, and one later than 0.3 ms leaves no time to rehearse (README "Session 16")
        self._timer_slack_was = set_timer_slack_ns(1)
        gc.collect()
        gc.freeze()
        gc.disable()
        now = self._clock()
        self._next_s = now
        self._next_young_s = now + GC_YOUNG_EVERY_S
        self._next_older_s = now + GC_OLDER_EVERY_S
        self._running = True
        return note

    # ------------------------------------------------------------------ early ticks
    def request_tick(self) -> None:
        """From another thread: an input for the tick is ready (a detection fused), tick now
        rather than at the next deadline. Wakes the control thread if it sleeps."""
        with self._wake:
            self._requested = True
            self._wake.notify()

    def tick_here(self) -> float | None:
        """From the thread that has just handed an input over, still holding the lock it hands
        inputs over under: run the early tick on this thread, now, rather than wake the control
        thread for it. Only while the control thread sleeps with more than its lead (spin and
        rehearsal) to go, no request is pending and the minimum gap since the last tick has
        passed; the grid re-anchors one period after it as for any early tick, and the control
        thread, when it wakes, sleeps on to the new deadline. Returns the tick's start (call
        :meth:`tick_here_done` when it is over), or None: ask with :meth:`request_tick`."""
        with self._wake:
            now = self._clock()
            if (
                not self._running
                or self._busy
                or self._collecting
                or self._requested
                or now < self._last_start_s + self.min_gap_s
                or self._next_s - now <= self.spin_s + self.rehearse_lead_s
            ):
                return None
            self._busy = self._ticking_here = True
            self._next_s = now + self.period_s
            self._last_start_s = now
            self.early_ticks += 1
            self.ticks_here += 1
            return now

    def tick_here_done(self) -> None:
        """The tick :meth:`tick_here` started is over: the control thread, if it is waiting for
        it, and the threads waiting for slack go."""
        with self._wake:  # both at once: the control thread claims _busy under this lock
            self._ticking_here = self._busy = False
            self._wake.notify_all()
        self._tick_over(release_busy=False)

    def input_begins(self) -> None:
        """From the requesting thread, before it takes the lock to hand an input over (a
        fusion, some 0.3-1 ms): a tick falling due meanwhile waits for it, asleep, instead of
        spinning against it for the GIL and then waiting for the lock as tick work."""
        self._inputting = True

    def input_done(self) -> None:
        """The input is in (its tick asked for by :meth:`request_tick`) or came to nothing: a
        tick waiting for it goes on either way."""
        with self._wake:
            self._inputting = False
            self._wake.notify()

    def served(self) -> None:
        """On the control thread, as the tick takes its inputs (under the lock the requester
        holds while handing one over): the requests made so far are in this tick."""
        self._requested = False

    def _block_until_request(self, timeout_s: float) -> None:
        """Sleep ``timeout_s``, or less if a request comes (none pending: one that is already
        pending is waiting for the minimum gap, a plain sleep)."""
        with self._wake:
            if self._awaiting_input and not self._inputting:
                return  # the input came in before this lock was taken
            if not self._requested:
                self._wake.wait(timeout_s)
                return
            if not self._block_saw_request:
                return  # requested after the caller chose its timeout: let it choose again
        time.sleep(timeout_s)

    # ------------------------------------------------------------------ the grid
    def wait(self) -> float:
        """Return at the next deadline (sleeping, then spinning), or earlier when a tick was
        requested (not before ``min_gap_s`` after the last start: the grid then re-anchors
        there); when a stall left the loop more than a period behind, start afresh from now
        rather than run a burst of ticks."""
        clock = self._clock
        period = self.period_s
        early = False
        woken_as = ON_THE_GRID
        lead = self.spin_s + self.rehearse_lead_s
        slept = False
        while True:
            # read afresh after each sleep (a tick on another thread, tick_here, re-anchors
            # the grid) and, once awake, claimed under the same lock: from then on tick_here
            # leaves the tick to this thread
            with self._wake:
                while self._ticking_here:  # one is running: wait it out, asleep
                    self._wake.wait()
                now = clock()
                deadline = self._next_s
                stalled = now > deadline + period
                earliest = self._last_start_s + self.min_gap_s  # of an early tick
                target = deadline
                self._block_saw_request = self._requested
                if self._block_saw_request and earliest < deadline:
                    target = earliest if earliest > now else now
                if stalled or target - now <= lead:
                    self._busy = True
                    break
            self._block(target - now - lead)
            slept = True
        if stalled:
            self.stalls += 1
            start = now
            woken_as = STALL
        else:
            waited_from = None
            give_up = deadline + MAX_INPUT_WAIT_FRACTION * period
            if slept and not self._requested:
                self.wake_overshoot_s.append(now - (deadline - lead))
            if self.rehearse is not None:
                # not an early tick's (it starts at once), nor against a fusion for the GIL,
                # nor when woken too late for it
                if self._requested:
                    woken_as = EARLY_TICK
                elif self._inputting:
                    woken_as = FUSION
                elif deadline - now <= self.spin_s:
                    woken_as = WOKEN_LATE
                elif self.rehearse():
                    woken_as = REHEARSED
                    self.rehearsal_s.append(clock() - now)
                else:
                    woken_as = DECLINED
                if woken_as in self.rehearsals_skipped:
                    self.rehearsals_skipped[woken_as] += 1
            while True:
                now = clock()
                if self._inputting and not self._requested and now < give_up:
                    # a fusion is running: asleep until it is in (it asks for this tick)
                    # rather than spinning against it for the GIL, then waiting for the lock
                    if waited_from is None:
                        waited_from = now
                    self._awaiting_input = True
                    self._block_saw_request = False
                    self._block(give_up - now)
                    self._awaiting_input = False
                    continue
                if now >= deadline:
                    break
                if self._requested and now >= earliest:
                    early = True
                    break
            start = deadline
            if early:
                start = now
            elif waited_from is not None and now > deadline:  # late: re-anchored there
                start = now
                self.input_waits += 1
                self.input_wait_max_s = max(self.input_wait_max_s, now - deadline)
        self.early = early
        if early:
            self.early_ticks += 1
            woken_as = EARLY_TICK
        self.woken_as = woken_as
        self._next_s = start + period
        self._last_start_s = start
        return clock()

    def after_tick(self) -> None:
        """Let the threads waiting for slack go; collect garbage if due and there is slack
        before the next deadline (no tick starts on another thread meanwhile: tick_here)."""
        now = self._clock()
        if now < self._next_young_s or self._next_s - now < GC_MIN_SLACK_S:
            self._tick_over()
            return
        self._next_young_s = now + GC_YOUNG_EVERY_S
        self._collecting = True
        self._tick_over()
        try:
            if now >= self._next_older_s:
                self._next_older_s = now + GC_OLDER_EVERY_S
                gc.collect(1)
            else:
                gc.collect(0)
        finally:
            self._collecting = False
        self.gc_runs += 1

    def _tick_over(self, release_busy: bool = True) -> None:
        with self._done:
            if release_busy:
                self._busy = False
            self._ticks_done += 1
            self._done.notify_all()

    def slack_s(self) -> float:
        """Seconds left before the control thread wakes for the next tick (negative: late)."""
        return self._next_s - self.spin_s - self.rehearse_lead_s - self._clock()

    def _slack_for(self, margin_s: float) -> float | None:
        """The slack left after ``margin_s`` (s) while the control thread sleeps with more than
        that to go and no early tick is pending, else None."""
        with self._wake:  # as one: a tick starting on another thread moves both
            free = not self._busy and not self._requested
            slack = self.slack_s() - margin_s
        return slack if free and slack >= 0.0 else None

    def time_for(self, need_s: float) -> bool:
        """Would work of ``need_s`` (s) begun now on another thread end ``SLACK_LEAD_S`` before
        the control thread wakes (and no tick is pending or running)? Always True when the
        scheduler is not running."""
        return not self._running or self._slack_for(SLACK_LEAD_S + max(need_s, 0.0)) is not None

    def input_pending(self) -> bool:
        """Is an input being handed over (:meth:`input_begins`) or an early tick asked for?"""
        return self._inputting or self._requested

    def deadline_in_s(self) -> float:
        """Seconds left before the next deadline (negative: past it)."""
        return self._next_s - self._clock()

    def spin_in_s(self) -> float:
        """Seconds left before the spin to the next deadline begins (negative: spinning)."""
        return self._next_s - self.spin_s - self._clock()

    def wait_for_slack(self, need_s: float = 0.0) -> float | None:
        """For the other threads, before a piece of work that takes up to ``need_s`` (s):
        return at once while the control thread sleeps with more than ``SLACK_LEAD_S`` plus
        ``need_s`` to go before it wakes (``spin_s`` and the rehearsal's lead before its
        deadline) and no early tick is pending; otherwise when its tick is over. Their work
        then falls in the tick's slack, not at its start: under SCHED_FIFO a thread of the same
        priority is not preempted, so work begun just before the wake-up would delay the tick
        by its length, and otherwise the waking thread waits for the GIL (up to the switch
        interval) or for the loop's lock the work holds (README "Work sized to the slack").
        Returns how long the slack lasts from now (s, less ``SLACK_LEAD_S`` and ``need_s``:
        how long the caller may block on its own input and still be done before the control
        thread wakes; 0 after a tick that left less), None when the scheduler is not running."""
        if not self._running:
            return None
        margin = SLACK_LEAD_S + max(need_s, 0.0)
        slack = self._slack_for(margin)
        if slack is not None:
            return slack
        with self._done:
            n = self._ticks_done
            self._done.wait_for(
                lambda: self._ticks_done != n or not self._running,
                timeout=MAX_HOLD_OFF_S,
            )
        return max(self.slack_s() - margin, 0.0) if self._running else None

    def stop(self) -> None:
        """Hand collection back to the interpreter (and let any waiting thread go)."""
        self._running = False
        self._tick_over()
        with self._wake:
            self._wake.notify_all()
        if self._timer_slack_was is not None:
            set_timer_slack_ns(self._timer_slack_was)
            self._timer_slack_was = None
        gc.unfreeze()
        if self._gc_was_enabled:
            gc.enable()
        sys.setswitchinterval(self._switch_interval)
