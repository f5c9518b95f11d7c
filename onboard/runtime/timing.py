"""The control thread's timing figures: achieved rate and jitter over the last second (sent
in the telemetry), and over the run (ten minutes at most) the period, how late each wake-up
was, the work per tick, the overruns and the capture-to-command latency (``onboard run
--stats``, ``groundstation bench --sitl``). Pure bookkeeping: the runner hands it the
times."""

from __future__ import annotations

import math
from collections import deque


def percentile(xs, q: float) -> float | None:
    """The ``q`` quantile of ``xs`` (an element of it; None when empty)."""
    if not xs:
        return None
    s = sorted(xs)
    return s[min(len(s) - 1, int(q * len(s)))]


def to_ms(x: float | None) -> float | None:
    """Seconds to milliseconds (None stays None)."""
    return None if x is None else 1000.0 * x


def rate_hz(recent: list[tuple[float, float]]) -> float:
    """The achieved rate over (tick start s, period s) pairs, oldest first."""
    if len(recent) < 2:
        return 0.0
    span = sum(per for _, per in recent) - recent[0][1]
    return (len(recent) - 1) / span if span > 0 else 0.0


def jitter_p99_ms(recent: list[tuple[float, float]], period_s: float) -> float:
    """The 99th percentile of |period - nominal| over (tick start s, period s) pairs, ms."""
    if not recent:
        return 0.0
    dev = sorted(abs(per - period_s) for _, per in recent)
    return 1000.0 * dev[min(len(dev) - 1, int(0.99 * len(dev)))]


class LoopTiming:
    def __init__(self, period_s: float, keep: int) -> None:
        self.period_s = period_s
        self.overruns = 0
        self._recent: deque[tuple[float, float]] = deque()  # (tick start, period), last 1 s
        self.periods_all: deque[float] = deque(maxlen=keep)
        self.wake_late_s: deque[float] = deque(maxlen=keep)  # tick start - its deadline
        self.tick_work_s: deque[float] = deque(maxlen=keep)
        self.tick_cpu_s: deque[float] = deque(maxlen=keep)  # the ticking thread's CPU time
        # the setpoint's send in each tick (NaN: none sent: not flying), in step with tick_work_s
        self.send_s: deque[float] = deque(maxlen=keep)
        self._send_s = math.nan
        self.latency_total_s: deque[float] = deque(maxlen=keep)
        self.latency_beyond_camera_s: deque[float] = deque(maxlen=keep)
        self.latency_after_detection_s: deque[float] = deque(maxlen=keep)
        self._last_start: float | None = None
        self._first_start: float | None = None
        # the overran ticks (the last 20): when (s after the first tick's start), the work and
        # the CPU time in it (s): a wait (the CPU, the host) or work of its own
        self.overran: deque[tuple[float, float, float | None]] = deque(maxlen=20)

    def tick_started(self, start_s: float, late_s: float = 0.0) -> None:
        """A tick started at ``start_s``, ``late_s`` after its deadline."""
        if self._first_start is None:
            self._first_start = start_s
        self._send_s = math.nan
        self.wake_late_s.append(late_s)
        if self._last_start is not None:
            per = start_s - self._last_start
            self.periods_all.append(per)
            self._recent.append((start_s, per))
            while self._recent and self._recent[0][0] < start_s - 1.0:
                self._recent.popleft()
        self._last_start = start_s

    def setpoint_sent(self, took_s: float) -> None:
        """The running tick's setpoint took ``took_s`` (wall time) to pack and hand to the
        link: part of its work."""
        self._send_s = took_s

    def tick_done(self, work_s: float, cpu_s: float | None = None) -> bool:
        """Record a tick's work (wall time, and the control thread's CPU time in it: the
        difference is waiting for the CPU or a lock); True when it overran its period."""
        self.tick_work_s.append(work_s)
        self.send_s.append(self._send_s)
        self._send_s = math.nan
        if cpu_s is not None:
            self.tick_cpu_s.append(cpu_s)
        if work_s > self.period_s:
            self.overruns += 1
            self.overran.append((self._last_start - self._first_start, work_s, cpu_s))
            return True
        return False

    def command_sent(
        self, sent_s: float, capture_s: float, received_s: float, detected_s: float | None = None
    ) -> None:
        """A command computed from a detection captured at ``capture_s``, received from the
        camera at ``received_s`` and out of the detector at ``detected_s`` went out at
        ``sent_s``."""
        self.latency_total_s.append(sent_s - capture_s)
        self.latency_beyond_camera_s.append(sent_s - received_s)
        if detected_s is not None:
            self.latency_after_detection_s.append(sent_s - detected_s)

    def recent_periods(self) -> list[tuple[float, float]]:
        """A copy of the last second's (tick start s, period s), for the figures off the
        control thread."""
        return list(self._recent)

    def loop_rate_hz(self) -> float:
        return rate_hz(self._recent)

    def jitter_p99_ms(self) -> float:
        return jitter_p99_ms(self._recent, self.period_s)

    def flying_figures(self) -> dict:
        """The setpoint's send and the ticks that flew the vehicle (sent a setpoint: the sortie,
        not the ticks before the start or after the end), in ms: the send's median and p99;
        the flying ticks' count, work median, p99 and max; and in the slowest 1 % of them the
        mean work and the mean part of it the send took."""
        pairs = zip(self.tick_work_s, self.send_s, strict=False)
        flying = [(w, s) for w, s in pairs if not math.isnan(s)]  # NaN: nothing sent
        works = [w for w, _ in flying]
        sends = [s for _, s in flying]
        tail_from = percentile(works, 0.99)
        tail = [(w, s) for w, s in flying if w >= tail_from]
        n = len(tail)
        return {
            "setpoint_send_median_ms": to_ms(percentile(sends, 0.5)),
            "setpoint_send_p99_ms": to_ms(percentile(sends, 0.99)),
            "flying_ticks": len(flying),
            "flying_tick_work_median_ms": to_ms(percentile(works, 0.5)),
            "flying_tick_work_p99_ms": to_ms(tail_from),
            "flying_tick_work_max_ms": to_ms(max(works, default=None)),
            "slowest_1pc_work_mean_ms": to_ms(sum(w for w, _ in tail) / n) if n else None,
            "slowest_1pc_send_mean_ms": to_ms(sum(s for _, s in tail) / n) if n else None,
        }

    def figures(self) -> dict:
        per = self.periods_all
        jit = [abs(p - self.period_s) for p in per]
        late = self.wake_late_s
        return {
            "ticks": len(per) + 1 if per else 0,
            "rate_hz": (len(per) / sum(per)) if per else None,
            "period_median_ms": to_ms(percentile(per, 0.5)),
            "jitter_p99_ms": to_ms(percentile(jit, 0.99)),
            "jitter_max_ms": None if not jit else 1000 * max(jit),
            "wake_late_median_ms": to_ms(percentile(late, 0.5)),
            "wake_late_p99_ms": to_ms(percentile(late, 0.99)),
            "wake_late_max_ms": to_ms(max(late, default=None)),
            "tick_work_median_ms": to_ms(percentile(self.tick_work_s, 0.5)),
            "tick_work_p99_ms": to_ms(percentile(self.tick_work_s, 0.99)),
            "tick_work_max_ms": to_ms(max(self.tick_work_s, default=None)),
            "tick_cpu_median_ms": to_ms(percentile(self.tick_cpu_s, 0.5)),
            "tick_cpu_p99_ms": to_ms(percentile(self.tick_cpu_s, 0.99)),
            **self.flying_figures(),
            "overruns": self.overruns,
            "overran_ticks": [
                {"at_s": at, "work_ms": to_ms(w), "cpu_ms": to_ms(c)} for at, w, c in self.overran
            ],
            "latency_total_median_ms": to_ms(percentile(self.latency_total_s, 0.5)),
            "latency_beyond_camera_median_ms": to_ms(percentile(self.latency_beyond_camera_s, 0.5)),
            "latency_beyond_camera_p99_ms": to_ms(percentile(self.latency_beyond_camera_s, 0.99)),
            "latency_after_detection_median_ms": to_ms(
                percentile(self.latency_after_detection_s, 0.5)
            ),
            "latency_after_detection_p99_ms": to_ms(
                percentile(self.latency_after_detection_s, 0.99)
            ),
            "detections_fused": len(self.latency_total_s),
        }
