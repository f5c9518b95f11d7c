"""The targets' motions as a compiled kernel (:mod:`onboard.jit`): :func:`target_step` moves
a :class:`~.targets.Target`'s state array in place, one physics step at a time, for every
motion of :data:`MOTIONS` (targets.py states them; target_reference.py is the readable
specification the kernel is checked against). :func:`.physics.physics_steps` calls it from
another file and names it in its ``uses`` (onboard/jit.py), so an edit here drops the
caller's cached machine code too.

The arithmetic follows the module's reference operation for operation (no fast-math); the
squares use ``math.pow(x, two)`` with ``two`` = 2.0 passed in at run time (a constant 2 would
be folded into ``x * x``, which rounds differently in about 0.1 % of cases).
"""

from __future__ import annotations

import math

import numpy as np

from onboard.jit import kernel

from ..scenario.physics import AIR_DENSITY_KG_M3, helium_gross_lift_n

# what this kernel reads from other files (its cache is dropped when one changes): the air
# density of scenario/physics.py
_USES = (helium_gross_lift_n,)


# motions as the kernel knows them
MOTIONS = (
    "static", "cv", "ca", "sinusoid", "circle", "takeoff", "escape", "tethered", "balloon", "track",
    "turn", "weave", "jink", "evade", "surge",
)  # fmt: skip
KIND_TETHERED, KIND_BALLOON = MOTIONS.index("tethered"), MOTIONS.index("balloon")
KIND_TRACK = MOTIONS.index("track")
# the parameter array Target.params: start position, velocity, acceleration (m, m/s, m/s^2),
# sinusoid amplitude (m) and angular rate (rad/s), circle centre (m), radius (m) and angular
# rate, takeoff start (s), escape top speed (m/s), tether anchor (m), drag factor
# 0.5 rho C_d A (kg/m), net lift (N), mass with added air mass (kg), rope length (m), and the
# exponent 2.0 of Python's ``x ** 2`` (libm's pow, as the Python code squares: a constant 2
# would be folded into x * x, which rounds differently in about 0.1 % of cases); a light
# target's (tethered, balloon) buffet: side-force coefficient amplitude, Strouhal number,
# diameter (m) and area (m^2)
T_P0, T_V0, T_A0, T_AMP, T_SIN_W, T_CENTER, T_RADIUS, T_CIRCLE_W = 0, 3, 6, 9, 12, 13, 16, 17
T_START, T_MAX_SPEED, T_ANCHOR, T_DRAG_K, T_LIFT, T_MASS, T_ROPE, T_TWO = (
    18,
    19,
    20,
    23,
    24,
    25,
    26,
    27,
)
T_CL, T_STROUHAL, T_DIA, T_AREA = 28, 29, 30, 31
# the manoeuvres (turn, weave, jink, evade, surge; targets.py): lateral acceleration (m/s^2;
# turn: + to the left), the weave's or surge's angular rate (rad/s), phase (rad) and
# amplitude (weave: m sideways; surge: m/s of speed), the trigger range (m; evade: <= 0 from
# the start), the jink's speed (m/s) and acceleration (m/s^2), the side (+1 left of the LOS,
# -1 right) and the weave's sideways or the surge's heading unit vector
T_LAT, T_MAN_W, T_MAN_PHASE, T_MAN_AMP, T_TRIGGER = 32, 33, 34, 35, 36
T_JINK_SPEED, T_JINK_ACCEL, T_SIDE, T_DIR = 37, 38, 39, 40
T_SIZE = 43
# the target's state Target.x: position, velocity (m, m/s ENU), the buffet's phase (rad),
# then a manoeuvre's: 1.0 once triggered (jink, evade), its horizontal direction (jink: the
# dart's unit vector; evade: the side, +1 or -1, then 1.0 when it started from rest) and the
# jink's sideways
# speed gained so far (m/s)
TX_PHASE, TX_TRIGGERED, TX_DIR, TX_GAINED = 6, 7, 8, 10
TX_SIZE = 11
KIND_TURN, KIND_WEAVE, KIND_JINK, KIND_EVADE, KIND_SURGE = 10, 11, 12, 13, 14


@kernel("void(i8, f8[::1], f8[:, ::1], f8[::1], f8, f8, f8, f8, f8, f8, f8, f8)", uses=_USES)
def target_step(
    kind: int,
    c: np.ndarray,
    track: np.ndarray,
    x: np.ndarray,
    t: float,
    dt: float,
    wx: float,
    wy: float,
    wz: float,
    ix: float,
    iy: float,
    iz: float,
) -> None:
    """Move the target of motion ``MOTIONS[kind]`` (parameters ``c``, T_* layout; ``track``
    rows (time s, x, y, z m) for a recorded track) to time ``t`` (s), a step of ``dt`` after
    the last, in the wind (wx, wy, wz) (m/s ENU, where it is), the interceptor at
    (ix, iy, iz) (m ENU; nan: unknown, nothing triggers): its state ``x`` (TX_* layout) in
    place. No motion goes below the ground: there the target stays at z = 0 with its vertical
    velocity no longer downward."""
    if kind == 0:  # static
        return
    if kind == 1:  # cv: p0 + v t
        x[0] = c[0] + c[3] * t
        x[1] = c[1] + c[4] * t
        x[2] = c[2] + c[5] * t
    elif kind == 2:  # ca: p0 + v t + a t^2 / 2
        x[0] = c[0] + c[3] * t + 0.5 * c[6] * t * t
        x[1] = c[1] + c[4] * t + 0.5 * c[7] * t * t
        x[2] = c[2] + c[5] * t + 0.5 * c[8] * t * t
        x[3] = c[3] + c[6] * t
        x[4] = c[4] + c[7] * t
        x[5] = c[5] + c[8] * t
    elif kind == 3:  # sinusoid: p0 + v t + amplitude sin(w t)
        w = c[12]
        sn, cs = math.sin(w * t), math.cos(w * t)
        x[0] = c[0] + c[3] * t + c[9] * sn
        x[1] = c[1] + c[4] * t + c[10] * sn
        x[2] = c[2] + c[5] * t + c[11] * sn
        x[3] = c[3] + c[9] * w * cs
        x[4] = c[4] + c[10] * w * cs
        x[5] = c[5] + c[11] * w * cs
    elif kind == 4:  # circle about the centre plus a drift
        r, w = c[16], c[17]
        cs, sn = math.cos(w * t), math.sin(w * t)
        x[0] = c[13] + r * cs + c[3] * t
        x[1] = c[14] + r * sn + c[4] * t
        x[2] = c[15] + c[5] * t
        x[3] = -r * w * sn + c[3]
        x[4] = r * w * cs + c[4]
        x[5] = c[5]
    elif kind == 5:  # takeoff: rests until start_s, then climbs at v
        tc = t - c[18]
        if tc < 0.0:  # max(t - start_s, 0.0)
            tc = 0.0
        x[0] = c[0] + c[3] * tc
        x[1] = c[1] + c[4] * tc
        x[2] = c[2] + c[5] * tc
        if t > c[18]:
            x[3], x[4], x[5] = c[3], c[4], c[5]
        else:
            x[3], x[4], x[5] = 0.0, 0.0, 0.0
    elif kind == 6:  # escape: accelerates up to its top speed
        v0, v1, v2 = x[3] + c[6] * dt, x[4] + c[7] * dt, x[5] + c[8] * dt
        two = c[27]
        speed = math.sqrt(math.pow(v0, two) + math.pow(v1, two) + math.pow(v2, two))
        top = c[19]
        if speed > top:
            v0, v1, v2 = v0 * top / speed, v1 * top / speed, v2 * top / speed
        x[3], x[4], x[5] = v0, v1, v2
        x[0], x[1], x[2] = x[0] + v0 * dt, x[1] + v1 * dt, x[2] + v2 * dt
    elif kind == 7 or kind == 8:  # a balloon: lift, drag and buffet of the air it is in
        two = c[27]
        r0, r1, r2 = wx - x[3], wy - x[4], wz - x[5]  # the air relative to the balloon
        speed = math.sqrt(math.pow(r0, two) + math.pow(r1, two) + math.pow(r2, two))
        k = c[23]
        f0, f1, f2 = k * speed * r0, k * speed * r1, k * speed * r2
        f2 += c[24]
        if c[28] > 0.0 and speed > 1e-6:
            # vortex shedding: a side force across the relative wind (horizontal), amplitude
            # C_L' q A, at the shedding frequency St |r| / D
            h = math.sqrt(r0 * r0 + r1 * r1)
            s0, s1 = (r1 / h, -r0 / h) if h > 1e-9 else (1.0, 0.0)
            side = c[28] * 0.5 * AIR_DENSITY_KG_M3 * speed * speed * c[31] * math.sin(x[6])
            f0, f1 = f0 + side * s0, f1 + side * s1
            phase = x[6] + 2.0 * math.pi * c[29] * speed / c[30] * dt
            if phase > 2.0 * math.pi:  # kept in [0, 2 pi) (a step adds far less than 2 pi)
                phase -= 2.0 * math.pi
            x[6] = phase
        m = c[25]
        v0, v1, v2 = x[3] + f0 / m * dt, x[4] + f1 / m * dt, x[5] + f2 / m * dt
        p0, p1, p2 = x[0] + v0 * dt, x[1] + v1 * dt, x[2] + v2 * dt
        # the rope: project back onto the sphere and drop the outward radial velocity
        d0, d1, d2 = p0 - c[20], p1 - c[21], p2 - c[22]
        dist = math.sqrt(math.pow(d0, two) + math.pow(d1, two) + math.pow(d2, two))
        rope = c[26]
        if kind == 7 and dist > rope:
            u0, u1, u2 = d0 / dist, d1 / dist, d2 / dist
            p0, p1, p2 = c[20] + u0 * rope, c[21] + u1 * rope, c[22] + u2 * rope
            vr = v0 * u0 + v1 * u1 + v2 * u2
            if vr > 0.0:
                v0, v1, v2 = v0 - vr * u0, v1 - vr * u1, v2 - vr * u2
        x[0], x[1], x[2] = p0, p1, p2
        x[3], x[4], x[5] = v0, v1, v2
    elif kind == 9:  # a recorded track, linear between samples, continued at its last velocity
        n = track.shape[0]
        lo, hi = 0, n  # bisect_right over the times
        while lo < hi:
            mid = (lo + hi) // 2
            if t < track[mid, 0]:
                hi = mid
            else:
                lo = mid + 1
        i = lo - 1
        if i < 0:
            i = 0
        if i > n - 2:
            i = n - 2
        span = track[i + 1, 0] - track[i, 0]
        v0 = (track[i + 1, 1] - track[i, 1]) / span
        v1 = (track[i + 1, 2] - track[i, 2]) / span
        v2 = (track[i + 1, 3] - track[i, 3]) / span
        x[3], x[4], x[5] = v0, v1, v2
        x[0] = track[i, 1] + v0 * (t - track[i, 0])
        x[1] = track[i, 2] + v1 * (t - track[i, 0])
        x[2] = track[i, 3] + v2 * (t - track[i, 0])
    elif kind == 10:  # turn: a coordinated turn at lat m/s^2 after start_s (+ to the left)
        v0, v1 = x[3], x[4]
        h = math.sqrt(v0 * v0 + v1 * v1)
        if t > c[18] and h > 1e-6:
            ang = c[32] / h * dt  # the turn rate lat / |v_h| over the step
            cs, sn = math.cos(ang), math.sin(ang)
            v0, v1 = cs * v0 - sn * v1, sn * v0 + cs * v1
        x[3], x[4] = v0, v1
        x[0], x[1], x[2] = x[0] + v0 * dt, x[1] + v1 * dt, x[2] + x[5] * dt
    elif kind == 11:  # weave: p0 + v t + A (sin(w t + phi) - sin phi) d
        w, ph, amp = c[33], c[34], c[35]
        s = amp * (math.sin(w * t + ph) - math.sin(ph))
        r = amp * w * math.cos(w * t + ph)
        x[0] = c[0] + c[3] * t + s * c[40]
        x[1] = c[1] + c[4] * t + s * c[41]
        x[2] = c[2] + c[5] * t + s * c[42]
        x[3] = c[3] + r * c[40]
        x[4] = c[4] + r * c[41]
        x[5] = c[5] + r * c[42]
    elif kind == 12 or kind == 13:  # jink, evade: triggered by the interceptor's range
        l0, l1 = x[0] - ix, x[1] - iy  # the LOS from the interceptor, horizontal
        lh = math.sqrt(l0 * l0 + l1 * l1)
        rng = math.sqrt(l0 * l0 + l1 * l1 + (x[2] - iz) * (x[2] - iz))
        v0, v1, v2 = x[3], x[4], x[5]
        if x[7] == 0.0 and lh > 1e-6 and (rng <= c[36] or (kind == 13 and c[36] <= 0.0)):
            x[7] = 1.0
            p0, p1 = -l1 / lh, l0 / lh  # left of the LOS
            if kind == 12:  # dart to the drawn side
                x[8], x[9] = c[39] * p0, c[39] * p1
            else:  # evade: the side the target already moves to, else the drawn one
                across = v0 * p0 + v1 * p1
                h = math.sqrt(v0 * v0 + v1 * v1)
                x[8] = c[39] if abs(across) <= 0.05 * h else (1.0 if across > 0.0 else -1.0)
                x[9] = 1.0 if h <= 0.1 else 0.0  # from rest: it speeds up along e
        if x[7] != 0.0 and kind == 12:
            dv = c[38] * dt
            if dv > c[37] - x[10]:  # min(a dt, what is left of the dart's speed)
                dv = c[37] - x[10]
            if dv > 0.0:
                v0, v1 = v0 + dv * x[8], v1 + dv * x[9]
                x[10] = x[10] + dv
        elif x[7] != 0.0 and lh > 1e-6:  # evade: turn toward e, across the LOS, at lat
            e0, e1 = -x[8] * l1 / lh, x[8] * l0 / lh
            h = math.sqrt(v0 * v0 + v1 * v1)
            if x[9] != 0.0:  # from rest: accelerate along e up to the top speed
                v0, v1 = v0 + c[32] * e0 * dt, v1 + c[32] * e1 * dt
                h1 = math.sqrt(v0 * v0 + v1 * v1)
                if h1 > c[19]:
                    v0, v1 = v0 * c[19] / h1, v1 * c[19] / h1
            elif h > 0.1:
                u0, u1 = v0 / h, v1 / h
                eu = e0 * u0 + e1 * u1
                a0, a1 = c[32] * (e0 - eu * u0), c[32] * (e1 - eu * u1)
                v0, v1 = v0 + a0 * dt, v1 + a1 * dt
                k = h / math.sqrt(v0 * v0 + v1 * v1)  # a turn: the speed stays
                v0, v1 = v0 * k, v1 * k
        x[3], x[4] = v0, v1
        x[0], x[1], x[2] = x[0] + v0 * dt, x[1] + v1 * dt, x[2] + v2 * dt
    elif kind == 14:  # surge: the speed s0 + S (sin(w t + phi) - sin phi) along u
        w, ph, amp = c[33], c[34], c[35]
        two = c[27]
        s0 = math.sqrt(math.pow(c[3], two) + math.pow(c[4], two) + math.pow(c[5], two))
        sph = math.sin(ph)
        d = (s0 - amp * sph) * t + amp / w * (math.cos(ph) - math.cos(w * t + ph))
        s = s0 + amp * (math.sin(w * t + ph) - sph)
        x[0], x[1], x[2] = c[0] + d * c[40], c[1] + d * c[41], c[2] + d * c[42]
        x[3], x[4], x[5] = s * c[40], s * c[41], s * c[42]
    # the ground (z = 0) stops every motion: a target that would go below it stays on it
    # with no downward velocity (its horizontal motion goes on)
    if x[2] < 0.0:
        x[2] = 0.0
        if x[5] < 0.0:
            x[5] = 0.0
