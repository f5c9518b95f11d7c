"""Fault injection for the control thread's timing (``onboard run --inject-delays SEED``):
each wake-up is delayed as a loaded or badly configured computer would delay it, so that the
loop's handling of real elapsed and hold times can be tested in closed loop.

The delays, seeded: an exponential delay on every wake-up whose 99th percentile is
``p99_s`` (5 ms), a stall of ``stall_s`` (30 ms) once every ``stall_every_s`` (1 s), and one
freeze of ``freeze_s`` (150 ms) ``freeze_at_s`` (4 s) after the loop starts.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass

_LN_100 = math.log(100.0)  # an exponential's p99 is ln(100) times its mean


@dataclass(frozen=True)
class WakeDelayConfig:
    p99_s: float = 0.005
    stall_s: float = 0.030
    stall_every_s: float = 1.0
    freeze_s: float = 0.150
    freeze_at_s: float = 4.0


class WakeDelays:
    """How long to delay each wake-up: :meth:`next_s` with the wake-up's deadline (s since the
    loop's start, increasing) returns the extra sleep (s). Deterministic for a ``seed``."""

    def __init__(self, seed: int, config: WakeDelayConfig | None = None) -> None:
        self.config = config or WakeDelayConfig()
        self._rng = random.Random(seed)
        self._next_stall_s = self.config.stall_every_s
        self._frozen = False
        self.stalls = 0
        self.freezes = 0

    def next_s(self, since_start_s: float) -> float:
        c = self.config
        delay = self._rng.expovariate(_LN_100 / c.p99_s) if c.p99_s > 0.0 else 0.0
        if c.stall_every_s > 0.0 and since_start_s >= self._next_stall_s:
            self._next_stall_s += c.stall_every_s * math.ceil(
                (since_start_s - self._next_stall_s + 1e-12) / c.stall_every_s
            )
            delay += c.stall_s
            self.stalls += 1
        if not self._frozen and since_start_s >= c.freeze_at_s:
            self._frozen = True
            delay += c.freeze_s
            self.freezes += 1
        return delay
