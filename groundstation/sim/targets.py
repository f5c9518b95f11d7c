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
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

from ..scenario import TargetSpec
from ..scenario.physics import AIR_DENSITY_KG_M3, balloon_lift_and_mass


class Target:
    def __init__(self, spec: TargetSpec) -> None:
        self.spec = spec
        self.p = list(spec.position_m)
        self.v = (
            [0.0, 0.0, 0.0] if spec.motion in ("static", "takeoff") else list(spec.velocity_m_s)
        )
        self.radius_m = spec.diameter_m / 2.0
        self.moves = spec.motion != "static"  # False: advance() never changes it
        s = spec
        if s.motion == "circle":
            self._center = (s.position_m[0] - s.radius_m, s.position_m[1], s.position_m[2])
            self._omega = 2.0 * math.pi / s.period_s
            self.v = [
                v + d
                for v, d in zip(s.velocity_m_s, (0.0, s.radius_m * self._omega, 0.0), strict=True)
            ]
        if s.motion == "sinusoid":
            w = 2.0 * math.pi / s.period_s
            self.v = [v + a * w for v, a in zip(s.velocity_m_s, s.amplitude_m, strict=True)]
        if s.motion == "tethered":
            self._anchor = (s.position_m[0], s.position_m[1], s.position_m[2] - s.tether_length_m)
            self._drag_k = 0.5 * AIR_DENSITY_KG_M3 * s.drag_coefficient * math.pi * self.radius_m**2
            self.net_lift_n, self.mass_kg = balloon_lift_and_mass(s)

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

    def advance(self, t: float, dt: float, wind: tuple[float, float, float]) -> None:
        s = self.spec
        m = s.motion
        if m == "static":
            return
        # written out per component: this runs at every physics step
        p0, v0, a0 = s.position_m, s.velocity_m_s, s.acceleration_m_s2
        if m == "cv":
            self.p = [p0[0] + v0[0] * t, p0[1] + v0[1] * t, p0[2] + v0[2] * t]
        elif m == "ca":
            self.p = [
                p0[0] + v0[0] * t + 0.5 * a0[0] * t * t,
                p0[1] + v0[1] * t + 0.5 * a0[1] * t * t,
                p0[2] + v0[2] * t + 0.5 * a0[2] * t * t,
            ]
            self.v = [v0[0] + a0[0] * t, v0[1] + a0[1] * t, v0[2] + a0[2] * t]
        elif m == "sinusoid":
            w = 2.0 * math.pi / s.period_s
            sn, cs = math.sin(w * t), math.cos(w * t)
            amp = s.amplitude_m
            self.p = [
                p0[0] + v0[0] * t + amp[0] * sn,
                p0[1] + v0[1] * t + amp[1] * sn,
                p0[2] + v0[2] * t + amp[2] * sn,
            ]
            self.v = [v0[0] + amp[0] * w * cs, v0[1] + amp[1] * w * cs, v0[2] + amp[2] * w * cs]
        elif m == "circle":
            c, r, w = self._center, s.radius_m, self._omega
            cs, sn = math.cos(w * t), math.sin(w * t)
            self.p = [c[0] + r * cs + v0[0] * t, c[1] + r * sn + v0[1] * t, c[2] + v0[2] * t]
            self.v = [-r * w * sn + v0[0], r * w * cs + v0[1], v0[2]]
        elif m == "takeoff":
            tc = max(t - s.start_s, 0.0)
            self.p = [p0[i] + v0[i] * tc for i in range(3)]
            self.v = list(v0) if t > s.start_s else [0.0, 0.0, 0.0]
        elif m == "escape":
            v = [self.v[i] + a0[i] * dt for i in range(3)]
            speed = math.sqrt(v[0] ** 2 + v[1] ** 2 + v[2] ** 2)
            if speed > s.max_speed_m_s:
                v = [c * s.max_speed_m_s / speed for c in v]
            self.v = v
            self.p = [self.p[i] + v[i] * dt for i in range(3)]
        elif m == "tethered":
            self._tether_step(dt, wind)

    def _tether_step(self, dt: float, wind: tuple[float, float, float]) -> None:
        s = self.spec
        rel = [wind[i] - self.v[i] for i in range(3)]
        speed = math.sqrt(rel[0] ** 2 + rel[1] ** 2 + rel[2] ** 2)
        f = [self._drag_k * speed * rel[i] for i in range(3)]
        f[2] += self.net_lift_n
        v = [self.v[i] + f[i] / self.mass_kg * dt for i in range(3)]
        p = [self.p[i] + v[i] * dt for i in range(3)]
        # the rope: project back onto the sphere and drop the outward radial velocity
        d = [p[i] - self._anchor[i] for i in range(3)]
        dist = math.sqrt(d[0] ** 2 + d[1] ** 2 + d[2] ** 2)
        if dist > s.tether_length_m:
            u = [c / dist for c in d]
            p = [self._anchor[i] + u[i] * s.tether_length_m for i in range(3)]
            vr = v[0] * u[0] + v[1] * u[1] + v[2] * u[2]
            if vr > 0.0:
                v = [v[i] - vr * u[i] for i in range(3)]
        self.p, self.v = p, v


class TrackTarget(Target):
    """A target that follows a recorded track (times, positions), linearly interpolated and
    continued at its last velocity after the end: for re-flying a recorded sortie."""

    def __init__(self, spec: TargetSpec, times_s: list[float], positions_m: list) -> None:
        super().__init__(spec)
        if len(times_s) < 2 or len(times_s) != len(positions_m):
            raise ValueError("a target track needs at least two (time, position) samples")
        self._t = list(times_s)
        self._p = [tuple(map(float, p)) for p in positions_m]
        self.moves = True
        self.p = list(self._p[0])
        self.v = self._velocity(0)

    def _velocity(self, i: int) -> list[float]:
        i = min(max(i, 0), len(self._t) - 2)
        dt = self._t[i + 1] - self._t[i]
        return [(b - a) / dt for a, b in zip(self._p[i], self._p[i + 1], strict=True)]

    def advance(self, t: float, dt: float, wind) -> None:
        import bisect

        i = min(max(bisect.bisect_right(self._t, t) - 1, 0), len(self._t) - 2)
        v = self._velocity(i)
        self.v = v
        self.p = [a + vi * (t - self._t[i]) for a, vi in zip(self._p[i], v, strict=True)]
