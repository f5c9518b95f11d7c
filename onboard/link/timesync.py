"""MAVLink TIMESYNC between the companion computer and PX4: the flight controller's sample
times (``time_usec``, ``time_boot_ms``: its boot clock) expressed in companion time.

A round trip gives t1 (companion clock, request sent), tc (the flight controller's clock when
it answered) and t4 (companion clock, reply received). With equal delays each way,
tc happened at companion time (t1 + t4) / 2, so one sample of the offset is
o = (t1 + t4) / 2 - tc, wrong by at most half the round trip (RTT). :class:`TimesyncEstimator`
keeps a window of samples, fits offset and skew (a line in tc) to the quickest quarter of them
(the least room for asymmetry), refuses round trips slower than ``max_rtt_s`` and restarts
when the flight controller's clock jumps (a reboot). It is pure: times in, estimate out.

:func:`on_timesync` and :func:`send_request` are the adapter's few lines: PX4 answers a
request ``(tc1=0, ts1=t1)`` with ``(tc1=its clock, ts1=t1)``, both in nanoseconds, and sends
its own requests, which the companion answers the same way.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass


@dataclass(frozen=True)
class TimesyncConfig:
    window: int = 128  # samples kept (12.8 s at 10 Hz): enough span for the skew
    min_samples: int = 8  # before the estimate is used
    max_rtt_s: float = 0.05  # a slower round trip says little: refused
    reset_s: float = 0.05  # this far off the fit, ``reset_after`` times in a row: restart
    reset_after: int = 3
    best_fraction: float = 0.25  # the quickest quarter of the window is fitted


class TimesyncEstimator:
    """Offset (companion - flight controller, s) and skew of the flight controller's clock."""

    def __init__(self, config: TimesyncConfig | None = None) -> None:
        self.config = config or TimesyncConfig()
        self._samples: deque[tuple[float, float, float]] = deque(maxlen=self.config.window)
        self._off_fit = 0
        self.offset_s: float | None = None  # at tc = ``_tc_ref``
        self.skew = 0.0  # d(offset)/d(tc): - (flight controller rate - 1)
        self._tc_ref = 0.0
        self.accepted = 0
        self.refused = 0
        self.resets = 0
        self.last_rtt_s: float | None = None
        self.last_tc_s: float | None = None

    @property
    def converged(self) -> bool:
        return self.offset_s is not None and len(self._samples) >= self.config.min_samples

    @property
    def min_rtt_s(self) -> float | None:
        return min((r for _, _, r in self._samples), default=None)

    def add(self, t1_s: float, tc_s: float, t4_s: float) -> bool:
        """One round trip (companion send, flight-controller answer, companion receipt, in
        seconds). Returns whether it was used."""
        rtt = t4_s - t1_s
        if not (math.isfinite(t1_s + tc_s + t4_s) and 0.0 <= rtt <= self.config.max_rtt_s):
            self.refused += 1
            return False
        self.last_rtt_s, self.last_tc_s = rtt, tc_s
        o = 0.5 * (t1_s + t4_s) - tc_s
        if self.converged and abs(o - self._predict_offset(tc_s)) > self.config.reset_s + rtt:
            self._off_fit += 1
            if self._off_fit < self.config.reset_after:
                self.refused += 1
                return False
            self._samples.clear()  # the other clock jumped: start again from here
            self.resets += 1
        self._off_fit = 0
        self._samples.append((tc_s, o, rtt))
        self.accepted += 1
        self._fit()
        return True

    def _fit(self) -> None:
        s = sorted(self._samples, key=lambda x: x[2])
        n = max(2, math.ceil(self.config.best_fraction * len(s)))
        best = s[:n]
        tc_ref = sum(x[0] for x in best) / len(best)
        o_mean = sum(x[1] for x in best) / len(best)
        sxx = sum((x[0] - tc_ref) ** 2 for x in best)
        span = max(x[0] for x in best) - min(x[0] for x in best)
        skew = 0.0
        if len(best) >= 4 and span > 1.0:  # a slope needs a few samples over a second or more
            skew = sum((x[0] - tc_ref) * (x[1] - o_mean) for x in best) / sxx
        self._tc_ref, self.offset_s, self.skew = tc_ref, o_mean, skew

    def _predict_offset(self, tc_s: float) -> float:
        return self.offset_s + self.skew * (tc_s - self._tc_ref)

    @property
    def offset_now_s(self) -> float | None:
        """The offset at the latest round trip (companion - flight controller, s)."""
        if not self.converged or self.last_tc_s is None:
            return None
        return self._predict_offset(self.last_tc_s)

    def to_companion(self, tc_s: float) -> float | None:
        """A flight-controller time in companion time, or ``None`` before convergence."""
        if not self.converged:
            return None
        return tc_s + self._predict_offset(tc_s)


# ---------------------------------------------------------------------- the adapter's part
def send_request(link, now_s: float) -> None:
    """A TIMESYNC request stamped with the companion clock (``ts1``, ns)."""
    link.send(link.mav.timesync_encode(0, int(now_s * 1e9)))


def on_timesync(link, estimator: TimesyncEstimator, msg, now_s: float) -> None:
    """Answer the flight controller's request, or take its answer to ours (``now_s``: when
    the reply arrived, companion clock). Replies to somebody else's request (a ``ts1`` that
    is not a recent time of ours) are ignored."""
    if msg.tc1 == 0:
        link.send(link.mav.timesync_encode(int(now_s * 1e9), msg.ts1))
        return
    t1 = msg.ts1 * 1e-9
    if 0.0 <= now_s - t1 <= 1.0:
        estimator.add(t1, msg.tc1 * 1e-9, now_s)
