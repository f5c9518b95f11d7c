"""The body's turn between two control ticks as the gyro measured it: the mean rate of the
samples since the last tick, and whether the previous tick's line of sight is taken through
this tick's attitude turned back by it rather than through the last tick's attitude estimate
(docs/core.md), with the stale attitudes and jumps seen counted for the diagnostics.

Pure: the samples, states and intervals are handed in; no clock, no I/O.
"""

from __future__ import annotations

import math

import numpy as np

from .datatypes import VehicleState
from .geometry import attitude_jump_rad

# an attitude that moved this much more (rad) than the gyro turned it since an on-time last tick
# was a stale one replaced (counted for the diagnostics; docs/core.md)
ATTITUDE_JUMP_RAD = 0.005
# beyond this many periods since the last tick (a stall) the gyro's turn is no better a guess
ATTITUDE_JUMP_MAX_PERIODS = 2.0
# an attitude not carried to the tick (older than fc_state's limit: a stalled stream) is stale
ATTITUDE_STALE_S = 1e-6


class GyroTurn:
    """:meth:`add` each gyro sample, :meth:`mean_rate` once a tick; :meth:`through_gyro`
    judges the tick's attitude against the last tick's (:attr:`prev_R_WB`, which the loop
    sets at the end of each tick)."""

    def __init__(self, nominal_dt_s: float) -> None:
        self.nominal_dt_s = nominal_dt_s  # the control period (s)
        self._sum = (0.0, 0.0, 0.0)  # floats: the sum of the rates since the last tick
        self._n = 0
        self.prev_R_WB: np.ndarray | None = None  # the last tick's body attitude
        self.attitude_jumps = 0  # ticks whose attitude jumped beyond the gyro's turn
        self.stale_attitude_ticks = 0  # ticks with an attitude not carried to them (likewise)

    def add(self, rates_flu_rad_s) -> None:
        """One gyro sample (rad/s FLU)."""
        s0, s1, s2 = self._sum
        r = rates_flu_rad_s
        r0, r1, r2 = r.tolist() if type(r) is np.ndarray else (float(c) for c in r)
        self._sum = (s0 + r0, s1 + r1, s2 + r2)
        self._n += 1

    def mean_rate(self, fallback_flu_rad_s: np.ndarray) -> np.ndarray:
        """The mean rate (rad/s FLU) of the samples added since the last call, or
        ``fallback_flu_rad_s`` (the state's body rates) when there were none."""
        n = self._n
        if not n:
            return fallback_flu_rad_s
        g0, g1, g2 = self._sum
        self._sum = (0.0, 0.0, 0.0)
        self._n = 0
        return np.array((g0 / n, g1 / n, g2 / n))

    def through_gyro(
        self, state: VehicleState, R_WB: np.ndarray, gyro: np.ndarray, dt: float
    ) -> bool:
        """Take the previous LOS through this tick's attitude turned back by the gyro (rad/s
        FLU, the mean since the last tick) over ``dt`` (s), not through the last tick's
        attitude estimate? Yes, except after a late tick (a stall: two fresh attitudes are
        then a better guess than the mean rate times the interval) or with non-finite rates.

        The difference of two attitude estimates carries the estimator's corrections between
        them (a heading fused from the magnetometer wanders by tenths of a degree within a
        second), which PNG would turn K times; the gyro measures the turn itself. Stale
        attitudes (not carried to the tick) and jumps (more than ATTITUDE_JUMP_RAD beyond the
        gyro's turn: a stale one replaced by a fresh one) are counted for the diagnostics."""
        R0 = self.prev_R_WB
        if R0 is None or dt > ATTITUDE_JUMP_MAX_PERIODS * self.nominal_dt_s:
            return False
        g0, g1, g2 = gyro.tolist()
        if not (math.isfinite(g0) and math.isfinite(g1) and math.isfinite(g2)):
            return False  # no turn to take back (propagate_rotation ignores such rates)
        q_at = state.attitude_time_s
        if q_at is not None and state.time_s - q_at > ATTITUDE_STALE_S:
            self.stale_attitude_ticks += 1
        elif attitude_jump_rad(R0, R_WB, g0, g1, g2, dt) > ATTITUDE_JUMP_RAD:
            self.attitude_jumps += 1
        return True
