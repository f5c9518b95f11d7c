"""Target motions (DESIGN.md §6). Each target has ``p`` and ``v`` (world ENU, lists of floats)
and ``advance(t_s, dt_s, wind)`` that moves it to time ``t_s``.

- static: stays at position_m
- cv: p0 + v t
- ca: p0 + v t + a t^2 / 2
- sinusoid: p0 + v t + amplitude * sin(2 pi t / period_s)
- circle: horizontal circle of radius_m through position_m, one lap per period_s (negative:
  clockwise seen from above), plus a drift velocity_m_s
- escape: starts with velocity_m_s and accelerates with acceleration_m_s2 up to max_speed_m_s
- takeoff: rests at position_m until start_s, then climbs at the constant velocity_m_s
- tethered: a helium balloon on a rope anchored tether_length_m below position_m (its rest
  position in still air), pulled up by its net lift and pushed by the drag of the wind at its
  position (quadratic, C_d 0.47), with its added air mass; lift and mass from the physics
  unless the file gives them (scenario/physics.py). It starts leaning at rest in
  the mean wind where it floats and swings with the gusts
- balloon: a free helium balloon, the same forces without the rope: it rises at the speed
  where drag balances its net lift and drifts with the air

Targets that manoeuvre (docs/agility.md; drawn per sortie from the target's own stream):

- turn: flies velocity_m_s and from start_s on turns horizontally with the lateral
  acceleration lateral_accel_m_s2 (a coordinated turn, + to the left; the speed stays)
- weave: p0 + v t + A (sin(2 pi t / T + phi) - sin phi) sideways (horizontal, left of
  velocity_m_s; east for a target without one), A drawn in [amplitude_min_m,
  amplitude_max_m], T in [period_s, period_max_s], phi in [0, 2 pi)
- jink: flies velocity_m_s (0: hovers) until the interceptor comes within trigger_range_m,
  then darts horizontally across the line of sight at jink_accel_m_s2 until it has gained
  jink_speed_m_s, to the side ``side`` (+1 left, -1 right, 0 drawn)
- evade: turns its horizontal velocity away from the interceptor's line of sight (toward the
  side it already moves to across it, else ``side``) with lateral_accel_m_s2, from the moment
  the interceptor is within trigger_range_m (0: from the start); up to max_speed_m_s from rest
- surge: flies along velocity_m_s, its speed |v0| + S (sin(2 pi t / T + phi) - sin phi),
  S = speed_change_m_s, T drawn in [period_s, period_max_s], phi in [0, 2 pi)

A light target (tethered, balloon) feels the air where it is: the wind with its turbulence,
the interceptor's rotor wash, and the side force of the vortices it sheds (buffet:
C_L' 0.5 rho |v_a|^2 A sin(phase), across the relative wind, at St |v_a| / D, its starting
phase drawn per sortie; docs/air.md). No motion goes below the ground (z = 0): a target that
would stays on it, its vertical velocity no longer downward, its horizontal motion going on.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from ..scenario import TargetSpec
from ..scenario.physics import AIR_DENSITY_KG_M3, balloon_lift_and_mass
from .target_kernels import (
    KIND_TRACK,
    MOTIONS,
    T_A0,
    T_AMP,
    T_ANCHOR,
    T_AREA,
    T_CENTER,
    T_CIRCLE_W,
    T_CL,
    T_DIA,
    T_DIR,
    T_DRAG_K,
    T_JINK_ACCEL,
    T_JINK_SPEED,
    T_LAT,
    T_LIFT,
    T_MAN_AMP,
    T_MAN_PHASE,
    T_MAN_W,
    T_MASS,
    T_MAX_SPEED,
    T_P0,
    T_RADIUS,
    T_ROPE,
    T_SIDE,
    T_SIN_W,
    T_SIZE,
    T_START,
    T_STROUHAL,
    T_TRIGGER,
    T_TWO,
    T_V0,
    TX_SIZE,
    target_step,
)

MANOEUVRES = ("turn", "weave", "jink", "evade", "surge")
_NOWHERE = (math.nan, math.nan, math.nan)  # no interceptor: nothing triggers


def _slot(i: int) -> property:
    """A list view of x[i:i+3] (a copy: assign the whole vector to change it)."""

    def get(self: Target) -> list[float]:
        return self.x[i : i + 3].tolist()

    def put(self: Target, value) -> None:
        self.x[i : i + 3] = value

    return property(get, put)


class Target:
    """A target: position ``p`` and velocity ``v`` (lists, m and m/s ENU) over the state
    array :attr:`x`, moved by :func:`.target_kernels.target_step` with :attr:`kind` and
    :attr:`params`."""

    p = _slot(0)
    v = _slot(3)

    def __init__(self, spec: TargetSpec, rng: np.random.Generator | None = None) -> None:
        """``rng`` draws a light target's buffet phase (0 without it) and a manoeuvre's
        period, amplitude, phase and side (the ranges' lower ends, phase 0 and left without
        it)."""
        self.spec = spec
        s = spec
        self.kind = MOTIONS.index(s.motion)
        self.x = np.zeros(TX_SIZE)
        self.track = np.zeros((0, 4))  # (time s, x, y, z m) rows of a recorded track
        self.p = list(s.position_m)
        self.v = [0.0, 0.0, 0.0] if s.motion in ("static", "takeoff") else list(s.velocity_m_s)
        self.radius_m = s.diameter_m / 2.0
        self.moves = s.motion != "static"  # False: advance() never changes it
        c = np.zeros(T_SIZE)
        c[T_P0 : T_P0 + 3] = s.position_m
        c[T_V0 : T_V0 + 3] = s.velocity_m_s
        c[T_A0 : T_A0 + 3] = s.acceleration_m_s2
        c[T_MAX_SPEED] = s.max_speed_m_s
        c[T_START] = s.start_s
        c[T_TWO] = 2.0
        if s.motion == "circle":
            self._center = (s.position_m[0] - s.radius_m, s.position_m[1], s.position_m[2])
            self._omega = 2.0 * math.pi / s.period_s
            self.v = [
                v + d
                for v, d in zip(s.velocity_m_s, (0.0, s.radius_m * self._omega, 0.0), strict=True)
            ]
            c[T_CENTER : T_CENTER + 3] = self._center
            c[T_RADIUS], c[T_CIRCLE_W] = s.radius_m, self._omega
        if s.motion == "sinusoid":
            w = 2.0 * math.pi / s.period_s
            self.v = [v + a * w for v, a in zip(s.velocity_m_s, s.amplitude_m, strict=True)]
            c[T_AMP : T_AMP + 3] = s.amplitude_m
            c[T_SIN_W] = w
        if s.motion in MANOEUVRES:
            self._manoeuvre(s, c, rng)
        self.light = s.motion in ("tethered", "balloon")  # moved by the air
        if self.light:
            self._anchor = (s.position_m[0], s.position_m[1], s.position_m[2] - s.tether_length_m)
            area = math.pi * self.radius_m**2
            self._drag_k = 0.5 * AIR_DENSITY_KG_M3 * s.drag_coefficient * area
            self.net_lift_n, self.mass_kg = balloon_lift_and_mass(s)
            c[T_ANCHOR : T_ANCHOR + 3] = self._anchor
            c[T_DRAG_K], c[T_LIFT], c[T_MASS] = self._drag_k, self.net_lift_n, self.mass_kg
            c[T_ROPE] = s.tether_length_m
            c[T_CL], c[T_STROUHAL] = s.buffet_lift_coefficient, s.strouhal_number
            c[T_DIA], c[T_AREA] = s.diameter_m, area
            self.x[6] = 0.0 if rng is None else float(rng.uniform(0.0, 2.0 * math.pi))
        self.params = c

    def _manoeuvre(self, s: TargetSpec, c: np.ndarray, rng: np.random.Generator | None) -> None:
        """A manoeuvre's constants in ``c`` (T_* layout), drawn with ``rng``."""

        def draw(lo: float, hi: float) -> float:
            return lo if rng is None or hi <= lo else float(rng.uniform(lo, hi))

        period = draw(s.period_s, s.period_max_s)
        c[T_MAN_W] = 2.0 * math.pi / period if period > 0.0 else 0.0
        c[T_MAN_PHASE] = draw(0.0, 2.0 * math.pi)
        side = s.side if s.side != 0.0 else (1.0 if rng is None or rng.uniform() < 0.5 else -1.0)
        c[T_SIDE] = side
        c[T_LAT] = s.lateral_accel_m_s2
        c[T_TRIGGER] = s.trigger_range_m
        c[T_JINK_SPEED], c[T_JINK_ACCEL] = s.jink_speed_m_s, s.jink_accel_m_s2
        v0 = np.array(s.velocity_m_s)
        if s.motion == "weave":
            c[T_MAN_AMP] = draw(s.amplitude_min_m, s.amplitude_max_m)
            h = math.hypot(v0[0], v0[1])
            c[T_DIR : T_DIR + 3] = (-v0[1] / h, v0[0] / h, 0.0) if h > 1e-9 else (1.0, 0.0, 0.0)
            w, ph = c[T_MAN_W], c[T_MAN_PHASE]
            self.v = (v0 + c[T_MAN_AMP] * w * math.cos(ph) * c[T_DIR : T_DIR + 3]).tolist()
        if s.motion == "surge":
            c[T_MAN_AMP] = s.speed_change_m_s
            c[T_DIR : T_DIR + 3] = v0 / np.linalg.norm(v0)

    def settle_in_wind(self, wind_at: Callable[[list[float]], Sequence[float]]) -> None:
        """Tethered: start leaning at rest in the mean wind (rope along lift + drag), as a
        balloon would be when the sortie begins, ``wind_at(p)`` giving the mean wind where it
        floats (a fixed point, damped, for a wind that varies in space); other motions are
        unaffected."""
        if self.spec.motion != "tethered":
            return
        length = self.spec.tether_length_m
        p = list(self.spec.position_m)
        for _ in range(60):
            wind = wind_at(p)
            speed = math.sqrt(sum(c * c for c in wind))
            f = [self._drag_k * speed * c for c in wind]
            f[2] += self.net_lift_n
            n = math.sqrt(sum(c * c for c in f))
            new = [self._anchor[i] + length * f[i] / n for i in range(3)]
            p = [0.5 * (a + b) for a, b in zip(p, new, strict=True)]
        self.p = p
        self.v = [0.0, 0.0, 0.0]

    def advance(
        self,
        t: float,
        dt: float,
        wind: Sequence[float],
        interceptor_m: Sequence[float] = _NOWHERE,
    ) -> None:
        """Move to time ``t`` (s), ``dt`` after the last call, in ``wind`` (m/s ENU, where
        the target is), the interceptor at ``interceptor_m`` (m ENU; the jink and evasion
        react to it, nothing triggers without it): :func:`.target_kernels.target_step`."""
        i0, i1, i2 = interceptor_m
        target_step(
            self.kind, self.params, self.track, self.x, t, dt, wind[0], wind[1], wind[2],
            float(i0), float(i1), float(i2),
        )  # fmt: skip


class TrackTarget(Target):
    """A target that follows a recorded track (times, positions), linearly interpolated and
    continued at its last velocity after the end: for re-flying a recorded sortie. A sample
    at the time of the one before it (a log may record two at one stamp) is dropped; times that
    go back, or a sample that is not finite, are refused (ValueError)."""

    def __init__(self, spec: TargetSpec, times_s: list[float], positions_m: list) -> None:
        super().__init__(spec)
        self.light = False
        if len(times_s) != len(positions_m):
            raise ValueError("a target track needs one position per time")
        rows: list[tuple[float, ...]] = []
        for i, (t, p) in enumerate(zip(times_s, positions_m, strict=True)):
            row = (float(t), *map(float, p))
            if len(row) != 4 or not all(math.isfinite(c) for c in row):
                raise ValueError(f"target track sample {i}: not a finite time and 3-D position")
            if rows and row[0] <= rows[-1][0]:
                if row[0] == rows[-1][0]:
                    continue  # a repeated stamp: the first sample at it stands
                raise ValueError(
                    f"target track sample {i}: time {row[0]} s before the previous {rows[-1][0]} s"
                )
            rows.append(row)
        if len(rows) < 2:
            raise ValueError("a target track needs at least two (time, position) samples")
        self.kind = KIND_TRACK
        self.track = np.array(rows)
        self.moves = True
        t0 = self.track[0, 0]
        self.advance(t0, 0.0, (0.0, 0.0, 0.0))  # the first segment's velocity
        self.p = self.track[0, 1:].tolist()
