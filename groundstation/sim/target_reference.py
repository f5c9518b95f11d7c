"""The targets' motions (:func:`.target_kernels.target_step`) written as they are stated
(targets.py, docs/agility.md, docs/air.md): numpy vectors in world ENU, SI units. The
specification the compiled kernel is checked against (tests/test_kernel_references.py); the
simulator does not call it."""

from __future__ import annotations

import math

import numpy as np

from ..scenario.physics import AIR_DENSITY_KG_M3
from . import target_kernels as TK  # noqa: N812

E_UP = np.array([0.0, 0.0, 1.0])
RHO = AIR_DENSITY_KG_M3  # kg/m^3, sea level, 20 C


def balloon_force(
    v_rel: np.ndarray,
    phase_rad: float,
    drag_k: float,
    net_lift_n: float,
    c_l: float,
    area_m2: float,
) -> np.ndarray:
    """The air's force (N) on a light target with the air moving at v_r (m/s) relative to it:

        F = k |v_r| v_r + L e_z + C_L' (rho / 2) |v_r|^2 A sin(phase) s^

    quadratic drag (k = 0.5 rho C_d A, kg/m), the net lift L (N), and the buffet of its shed
    vortices: horizontal, across the relative wind, s^ = (v_r x e_z) / |v_r x e_z| ((1, 0, 0)
    when the air moves vertically only), none without a wake (C_L' = 0 or |v_r| <= 1e-6 m/s)
    (docs/air.md; Achenbach 1974, Howe, Lauchle & Wang 2001)."""
    speed = float(np.linalg.norm(v_rel))
    force = drag_k * speed * v_rel + net_lift_n * E_UP
    if c_l > 0.0 and speed > 1e-6:
        across = np.cross(v_rel, E_UP)
        h = float(np.linalg.norm(across))
        side = across / h if h > 1e-9 else np.array([1.0, 0.0, 0.0])
        force = force + c_l * 0.5 * RHO * speed**2 * area_m2 * math.sin(phase_rad) * side
    return force


def _left_of(d: np.ndarray) -> np.ndarray:
    """The horizontal unit vector 90 degrees to the left of the horizontal vector d."""
    return np.array([-d[1], d[0], 0.0]) / math.hypot(d[0], d[1])


def manoeuvre_state(
    kind: str, c: np.ndarray, x: np.ndarray, t: float, dt: float, interceptor: np.ndarray
) -> np.ndarray:
    """The state (TX_* array) of a manoeuvring target at time t (s), a step of dt after ``x``,
    the interceptor at ``interceptor`` (m; nan: unknown, nothing triggers):

    - turn: after t_start the horizontal velocity turns at omega = a_lat / |v_h| (a
      coordinated turn of lateral acceleration a_lat, + to the left; the speed stays), rotated
      exactly over the step; p <- p + v dt;
    - weave: p = p0 + v0 t + A (sin(w t + phi) - sin phi) d, v its derivative (A, w = 2 pi / T
      and phi drawn per sortie, d the horizontal unit left of v0);
    - jink: at constant velocity until the interceptor is within the trigger range R_j; then
      it darts horizontally across the LOS (to the drawn side) at a_j until it has gained the
      dart's speed v_j; p <- p + v dt;
    - evade: from the trigger range on (from the start if R_j <= 0) it turns its horizontal
      velocity toward e, the horizontal unit across the LOS on the side it already moves to (the
      drawn side when it moves within 3 degrees of the LOS), with a = a_lat (e - (e . u) u),
      u = v_h / |v_h| (a turn: the speed kept); a target at rest when it starts (|v_h| <= 0.1
      m/s) accelerates along e at a_lat up to the top speed instead;
    - surge: along u = v0 / |v0| at the speed s(t) = |v0| + S (sin(w t + phi) - sin phi),
      p = p0 + u integral of s."""
    p, v = x[0:3].copy(), x[3:6].copy()
    out = x.copy()
    p0, v0 = c[TK.T_P0 : TK.T_P0 + 3], c[TK.T_V0 : TK.T_V0 + 3]
    a_lat, w, phi, amp = c[TK.T_LAT], c[TK.T_MAN_W], c[TK.T_MAN_PHASE], c[TK.T_MAN_AMP]
    d = c[TK.T_DIR : TK.T_DIR + 3]
    if kind == "turn":
        h = math.hypot(v[0], v[1])
        if t > c[TK.T_START] and h > 1e-6:
            ang = a_lat / h * dt
            rot = np.array([[math.cos(ang), -math.sin(ang)], [math.sin(ang), math.cos(ang)]])
            v[0:2] = rot @ v[0:2]
        p = p + v * dt
    elif kind == "weave":
        p = p0 + v0 * t + amp * (math.sin(w * t + phi) - math.sin(phi)) * d
        v = v0 + amp * w * math.cos(w * t + phi) * d
    elif kind in ("jink", "evade"):
        los = p - interceptor
        los_h = math.hypot(los[0], los[1])
        if not out[TK.TX_TRIGGERED] and los_h > 1e-6:
            near = float(np.linalg.norm(los)) <= c[TK.T_TRIGGER]
            if near or (kind == "evade" and c[TK.T_TRIGGER] <= 0.0):
                out[TK.TX_TRIGGERED] = 1.0
                left = _left_of(los)
                if kind == "jink":
                    out[TK.TX_DIR : TK.TX_DIR + 2] = c[TK.T_SIDE] * left[0:2]
                else:
                    across, speed = float(v @ left), math.hypot(v[0], v[1])
                    if abs(across) <= 0.05 * speed:
                        out[TK.TX_DIR] = c[TK.T_SIDE]
                    else:
                        out[TK.TX_DIR] = math.copysign(1.0, across)
                    out[TK.TX_DIR + 1] = 1.0 if speed <= 0.1 else 0.0
        if out[TK.TX_TRIGGERED] and kind == "jink":
            dv = min(c[TK.T_JINK_ACCEL] * dt, c[TK.T_JINK_SPEED] - out[TK.TX_GAINED])
            if dv > 0.0:
                v[0:2] = v[0:2] + dv * out[TK.TX_DIR : TK.TX_DIR + 2]
                out[TK.TX_GAINED] += dv
        elif out[TK.TX_TRIGGERED] and los_h > 1e-6:
            e = out[TK.TX_DIR] * _left_of(los)
            h = math.hypot(v[0], v[1])
            if out[TK.TX_DIR + 1]:
                v[0:2] = v[0:2] + a_lat * e[0:2] * dt
                h1 = math.hypot(v[0], v[1])
                if h1 > c[TK.T_MAX_SPEED]:
                    v[0:2] = v[0:2] * (c[TK.T_MAX_SPEED] / h1)
            elif h > 0.1:
                u = np.array([v[0], v[1], 0.0]) / h
                turned = v[0:2] + a_lat * (e - float(e @ u) * u)[0:2] * dt
                v[0:2] = turned * (h / float(np.linalg.norm(turned)))
        p = p + v * dt
    elif kind == "surge":
        s0 = float(np.linalg.norm(v0))
        travelled = (s0 - amp * math.sin(phi)) * t + amp / w * (
            math.cos(phi) - math.cos(w * t + phi)
        )
        speed = s0 + amp * (math.sin(w * t + phi) - math.sin(phi))
        p, v = p0 + travelled * d, speed * d
    out[0:3], out[3:6] = p, v
    return out


def target_state(
    kind: str,
    c: np.ndarray,
    track: np.ndarray,
    x: np.ndarray,
    t: float,
    dt: float,
    air: np.ndarray,
    interceptor: np.ndarray,
) -> np.ndarray:
    """The target's state (position m, velocity m/s, buffet phase rad, a manoeuvre's state;
    the TX_* array) at time t (s), a step of dt after ``x``, for each motion (targets.py),
    ``air`` the wind where it is (m/s; a light target's), ``interceptor`` where the
    interceptor is (m; the manoeuvres that react to it):

    - static: where it was put;
    - cv: p = p0 + v0 t (velocity as given);  ca: p = p0 + v0 t + a t^2 / 2, v = v0 + a t;
    - sinusoid: p = p0 + v0 t + A sin(w t), v = v0 + A w cos(w t);
    - circle: p = c + r (cos w t, sin w t, 0) + v0 t, v = r w (-sin w t, cos w t, 0) + v0;
    - takeoff: p = p0 + v0 max(t - t_start, 0), v = v0 after t_start, 0 before;
    - escape: v <- v + a dt, scaled down to the top speed; p <- p + v dt;
    - tethered, balloon: v <- v + F / m dt (:func:`balloon_force` with v_r = air - v, m with
      the added air mass), p <- p + v dt; the buffet's phase advances by 2 pi St |v_r| / D dt
      (mod 2 pi; Strouhal shedding); a tethered one is held by its rope: beyond the rope's
      length from the anchor it is put back onto that sphere and its outward radial velocity
      dropped;
    - track: linear between the recorded samples, continued at the last velocity;
    - turn, weave, jink, evade, surge: :func:`manoeuvre_state`.

    Then the ground: a moving target below z = 0 is put on it and its vertical velocity is
    no longer downward (its horizontal motion goes on)."""
    p0, v0, a0 = c[TK.T_P0 : TK.T_P0 + 3], c[TK.T_V0 : TK.T_V0 + 3], c[TK.T_A0 : TK.T_A0 + 3]
    p, v, phase = x[0:3].copy(), x[3:6].copy(), float(x[6])
    rest = x[7:].copy()
    if kind == "static":
        return x.copy()
    if kind == "cv":
        p = p0 + v0 * t
    elif kind == "ca":
        p, v = p0 + v0 * t + 0.5 * a0 * t * t, v0 + a0 * t
    elif kind == "sinusoid":
        amplitude, w = c[TK.T_AMP : TK.T_AMP + 3], c[TK.T_SIN_W]
        p, v = p0 + v0 * t + amplitude * math.sin(w * t), v0 + amplitude * w * math.cos(w * t)
    elif kind == "circle":
        centre, r, w = c[TK.T_CENTER : TK.T_CENTER + 3], c[TK.T_RADIUS], c[TK.T_CIRCLE_W]
        ring = np.array([math.cos(w * t), math.sin(w * t), 0.0])
        p = centre + r * ring + v0 * t
        v = r * w * np.array([-ring[1], ring[0], 0.0]) + v0
    elif kind == "takeoff":
        start_s = c[TK.T_START]
        p = p0 + v0 * max(t - start_s, 0.0)
        v = v0.copy() if t > start_s else np.zeros(3)
    elif kind == "escape":
        top_speed = c[TK.T_MAX_SPEED]
        v = v + a0 * dt
        speed = float(np.linalg.norm(v))
        if speed > top_speed:
            v = v * (top_speed / speed)
        p = p + v * dt
    elif kind in ("tethered", "balloon"):
        drag_k, net_lift_n, mass_kg = c[TK.T_DRAG_K], c[TK.T_LIFT], c[TK.T_MASS]
        c_l, strouhal, diameter_m, area_m2 = (
            c[TK.T_CL],
            c[TK.T_STROUHAL],
            c[TK.T_DIA],
            c[TK.T_AREA],
        )
        v_rel = air - v
        force = balloon_force(v_rel, phase, drag_k, net_lift_n, c_l, area_m2)
        speed = float(np.linalg.norm(v_rel))
        if c_l > 0.0 and speed > 1e-6:
            shedding_hz = strouhal * speed / diameter_m
            phase = math.fmod(phase + 2.0 * math.pi * shedding_hz * dt, 2.0 * math.pi)
        v = v + force / mass_kg * dt
        p = p + v * dt
        anchor, rope_m = c[TK.T_ANCHOR : TK.T_ANCHOR + 3], c[TK.T_ROPE]
        d = p - anchor
        if kind == "tethered" and np.linalg.norm(d) > rope_m:
            u = d / np.linalg.norm(d)
            p = anchor + rope_m * u
            v = v - max(float(v @ u), 0.0) * u
    elif kind == "track":
        times, points = track[:, 0], track[:, 1:4]
        i = min(max(int(np.searchsorted(times, t, side="right")) - 1, 0), len(track) - 2)
        v = (points[i + 1] - points[i]) / (times[i + 1] - times[i])
        p = points[i] + v * (t - times[i])
    else:
        moved = manoeuvre_state(kind, c, x, t, dt, interceptor)
        p, v, rest = moved[0:3], moved[3:6], moved[7:]
    if p[2] < 0.0:
        p[2], v[2] = 0.0, max(v[2], 0.0)
    return np.concatenate([p, v, [phase], rest])
