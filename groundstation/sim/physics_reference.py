"""The simulator's physics and camera kernels (:mod:`.physics`, :func:`.camera.sphere_image`)
written as the models are stated (DESIGN.md §6): numpy vectors in world ENU, body FLU,
quaternions (w, x, y, z) body -> world. The specification the compiled kernels are checked
against (tests/test_kernel_references.py); the simulator does not call them."""

from __future__ import annotations

import math

import numpy as np

from onboard.datatypes import GRAVITY_M_S2
from onboard.geometry_reference import (
    pixel_of,
    quaternion_product,
    rotation_of_quaternion,
)

from . import physics as P  # noqa: N812

G_ENU = np.array([0.0, 0.0, -GRAVITY_M_S2])


def vehicle_step(
    x: np.ndarray,
    rate_lag: float,
    thrust_lag: float,
    drag_1_s: float,
    mass_kg: float,
    dt: float,
    wind: np.ndarray,
) -> np.ndarray:
    """One rigid-body step of dt in the wind (the state x in the X_* layout, a new array):
    the body rates and thrust lag toward their commands by the per-step factors (first-order
    actuators), the attitude turns by the rates (q <- q exp(omega dt / 2) renormalised), then
    semi-implicit Euler of v' = (T / m) z_B - c (v - w) + g, p' = v (the step's kinematic
    acceleration kept), and the rates summed for the gyro's mean."""
    x = x.copy()
    omega = x[P.X_W : P.X_W + 3] + (x[P.X_CMD_W : P.X_CMD_W + 3] - x[P.X_W : P.X_W + 3]) * rate_lag
    x[P.X_RATE_SUM : P.X_RATE_SUM + 3] += omega
    x[P.X_RATE_N] += 1.0
    thrust = x[P.X_THRUST] + (x[P.X_CMD_THRUST] - x[P.X_THRUST]) * thrust_lag
    q = x[P.X_Q : P.X_Q + 4]
    angle = float(np.linalg.norm(omega)) * dt
    if angle > 1e-12:
        half = 0.5 * angle
        turn = np.array([math.cos(half), *(math.sin(half) / (angle / dt) * omega)])
        q = quaternion_product(q, turn)
        q = q / np.linalg.norm(q)
    z_B = rotation_of_quaternion(q)[:, 2]
    v = x[P.X_V : P.X_V + 3]
    acc = thrust / mass_kg * z_B - drag_1_s * (v - wind) + G_ENU
    v = v + acc * dt
    x[P.X_P : P.X_P + 3] += v * dt
    x[P.X_V : P.X_V + 3] = v
    x[P.X_Q : P.X_Q + 4] = q
    x[P.X_W : P.X_W + 3] = omega
    x[P.X_ACC : P.X_ACC + 3] = acc
    x[P.X_THRUST] = thrust
    return x


def gyro_mean(x: np.ndarray) -> np.ndarray:
    """The mean body rate since the last read (the IMU's averaged samples); the rate now if
    no step ran since."""
    n = x[P.X_RATE_N]
    return x[P.X_W : P.X_W + 3] if n == 0 else x[P.X_RATE_SUM : P.X_RATE_SUM + 3] / n


def normal_accel(x: np.ndarray) -> tuple[float, float]:
    """(|a - (a . v^) v^|, |v|^2) of the last step's acceleration a and velocity v (all of a
    below |v|^2 = 1e-9)."""
    a, v = x[P.X_ACC : P.X_ACC + 3], x[P.X_V : P.X_V + 3]
    vv = float(v @ v)
    along2 = float(a @ v) ** 2 / vv if vv > 1e-9 else 0.0
    return math.sqrt(max(float(a @ a) - along2, 0.0)), vv


def vehicle_command(
    rates: np.ndarray, thrust: float, max_rate: float, max_thrust_n: float
) -> tuple[np.ndarray, float]:
    """The commanded body rates clipped to +-max_rate per axis and the thrust clipped to
    [0, 1] times the maximum thrust (N)."""
    return np.clip(rates, -max_rate, max_rate), min(max(thrust, 0.0), 1.0) * max_thrust_n


def target_state(
    kind: str,
    c: np.ndarray,
    track: np.ndarray,
    x: np.ndarray,
    t: float,
    dt: float,
    wind: np.ndarray,
) -> np.ndarray:
    """The target's (position, velocity) at time t, a step of dt after ``x``, for each motion
    (targets.py): closed forms for cv, ca, sinusoid, circle and takeoff; escape accelerates to
    its top speed; the tethered balloon feels lift and quadratic drag and is held by its rope
    (projected back onto the sphere, outward radial velocity dropped); a track is linear
    between samples and continued at its last velocity."""
    p0, v0, a0 = c[P.T_P0 : P.T_P0 + 3], c[P.T_V0 : P.T_V0 + 3], c[P.T_A0 : P.T_A0 + 3]
    p, v = x[:3].copy(), x[3:].copy()
    if kind == "cv":
        p = p0 + v0 * t
    elif kind == "ca":
        p, v = p0 + v0 * t + 0.5 * a0 * t * t, v0 + a0 * t
    elif kind == "sinusoid":
        amp, w = c[P.T_AMP : P.T_AMP + 3], c[P.T_SIN_W]
        p, v = p0 + v0 * t + amp * math.sin(w * t), v0 + amp * w * math.cos(w * t)
    elif kind == "circle":
        r, w = c[P.T_RADIUS], c[P.T_CIRCLE_W]
        ring = np.array([math.cos(w * t), math.sin(w * t), 0.0])
        p = c[P.T_CENTER : P.T_CENTER + 3] + r * ring + v0 * t
        v = r * w * np.array([-ring[1], ring[0], 0.0]) + v0
    elif kind == "takeoff":
        start = c[P.T_START]
        p = p0 + v0 * max(t - start, 0.0)
        v = v0 if t > start else np.zeros(3)
    elif kind == "escape":
        v = v + a0 * dt
        speed, top = float(np.linalg.norm(v)), c[P.T_MAX_SPEED]
        if speed > top:
            v = v * (top / speed)
        p = p + v * dt
    elif kind == "tethered":
        rel = wind - v
        force = c[P.T_DRAG_K] * float(np.linalg.norm(rel)) * rel + np.array([0, 0, c[P.T_LIFT]])
        v = v + force / c[P.T_MASS] * dt
        p = p + v * dt
        anchor, rope = c[P.T_ANCHOR : P.T_ANCHOR + 3], c[P.T_ROPE]
        d = p - anchor
        if np.linalg.norm(d) > rope:
            u = d / np.linalg.norm(d)
            p = anchor + u * rope
            v = v - max(float(v @ u), 0.0) * u
    elif kind == "track":
        i = min(max(int(np.searchsorted(track[:, 0], t, side="right")) - 1, 0), len(track) - 2)
        v = (track[i + 1, 1:] - track[i, 1:]) / (track[i + 1, 0] - track[i, 0])
        p = track[i, 1:] + v * (t - track[i, 0])
    return np.concatenate([p, v])


def jet_factor(
    mean: np.ndarray, source: np.ndarray, dia: float, p: np.ndarray, on_axis: bool
) -> float:
    """U(x, r) / U_0 of a round fan jet along the mean wind from the outlet (wind.py): the
    centreline decay U_c / U_0 = min(B D / x, 1), times the Gaussian profile exp(-ln 2 r^2 /
    r_1/2^2), r_1/2 = max(D / 2, S x); 0 behind the fan or without a mean."""
    speed = float(np.linalg.norm(mean))
    if speed <= 0.0:
        return 0.0
    d = p - source
    x = float(d @ mean) / speed
    if x <= 0.0:
        return 0.0
    core = min(P.JET_DECAY_B * dia / x, 1.0)
    if on_axis:
        return core
    r2 = max(float(d @ d) - x * x, 0.0)
    r_half = max(0.5 * dia, P.JET_SPREAD_S * x)
    return core * math.exp(-math.log(2.0) * r2 / r_half**2)


def wind_at(x: np.ndarray, c: np.ndarray, p: np.ndarray) -> np.ndarray:
    """The wind at p: the state (mean + gust) times the jet's profile relative to its reference
    point (a uniform wind: the state itself)."""
    if c[P.W_JET] == 0.0:
        return x[:3]
    m, s = c[P.W_MEAN : P.W_MEAN + 3], c[P.W_SOURCE : P.W_SOURCE + 3]
    return jet_factor(m, s, c[P.W_DIA], p, False) / c[P.W_REF] * x[:3]


def gust_step(x: np.ndarray, c: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Gauss-Markov gusts g' = a g + b sigma n (n standard normals), and mean + g'."""
    g = c[P.W_A] * x[3:] + c[P.W_B] * c[P.W_SIGMA : P.W_SIGMA + 3] * normals
    return np.concatenate([c[P.W_MEAN : P.W_MEAN + 3] + g, g])


def closest_approach(r0: np.ndarray, r1: np.ndarray) -> tuple:
    """The closest approach of a relative position moving linearly from r0 to r1 over a step:
    s = clip(-r0 . d / |d|^2, 0, 1), d = r1 - r0; (|r0 + s d|, s, r0 + s d, r0 . d, r1 . d)."""
    d = r1 - r0
    s = min(max(-float(r0 @ d) / float(d @ d), 0.0), 1.0) if float(d @ d) > 0.0 else 0.0
    c = r0 + s * d
    return float(np.linalg.norm(c)), s, c, float(r0 @ d), float(r1 @ d)


def sphere_image(
    R_WC: np.ndarray, c: np.ndarray, t: np.ndarray, diameter_m: float, f_px: float, c_px: np.ndarray
) -> tuple[np.ndarray | None, float]:
    """A sphere of ``diameter_m`` at t seen by a pinhole camera at c: its centre's pixel
    (None behind the camera) and its image radius f R / sqrt(|p|^2 - R^2) (px), p = R_WC^T
    (t - c) (the tangent cone's half-angle)."""
    p_C = R_WC.T @ (t - c)
    R = diameter_m / 2.0
    return pixel_of(p_C, f_px, c_px), f_px * R / math.sqrt(max(float(p_C @ p_C) - R * R, 1e-12))


def physics_steps(
    k0: int, n: int, buf: np.ndarray, track: np.ndarray, normals: np.ndarray, ni: int
) -> tuple[int, np.ndarray]:
    """Steps k0 .. k0 + n of the sortie in ``buf`` (S_* layout), each: the command arrives
    when due, the vehicle steps in the wind where it is, the target moves (in the wind where
    it is), the gusts step; then the closest approach inside the step and the outcome: a hit
    or miss once the range opens within 3 m after closing, diverged (not finite or faster
    than 60 m/s), crashed (below the ground). Returns (steps taken, the new buffer)."""
    buf = buf.copy()
    vx = buf[P.S_VX : P.S_VX + P.X_SIZE]
    rate_lag, thrust_lag, drag, mass = buf[P.S_LAG : P.S_LAG + 4]
    tc, tx = buf[P.S_TC : P.S_TC + P.T_SIZE], buf[P.S_TX : P.S_TX + 6]
    wx, wc = buf[P.S_WX : P.S_WX + 6], buf[P.S_WC : P.S_WC + P.W_SIZE]
    cs, cmd = buf[P.S_CS : P.S_CS + P.C_SIZE], buf[P.S_CMD : P.S_CMD + 7]
    dt, kind = buf[P.S_DT], P.MOTIONS[int(buf[P.S_KIND])]
    for k in range(k0, k0 + n):
        t = k * dt
        if 0.0 <= cmd[0] <= k:
            rates, thrust = vehicle_command(cmd[1:4], cmd[4], cmd[5], cmd[6])
            vx[P.X_CMD_W : P.X_CMD_W + 3], vx[P.X_CMD_THRUST] = rates, thrust
            cmd[0] = -1.0
        vx[:] = vehicle_step(vx, rate_lag, thrust_lag, drag, mass, dt, wind_at(wx, wc, vx[:3]))
        p, v = vx[:3].copy(), vx[3:6].copy()
        if kind != "static":
            tx[:] = target_state(kind, tc, track, tx, t + dt, dt, wind_at(wx, wc, tx[:3]))
        if wc[P.W_SIGMA] > 0.0:
            wx[:] = gust_step(wx, wc, normals[ni])
            ni += 1
        r0, r1 = cs[P.C_REL : P.C_REL + 3].copy(), tx[:3] - p
        dist, s, closest, r0d, r1d = closest_approach(r0, r1)
        cs[P.C_REL : P.C_REL + 3] = r1
        if dist < cs[P.C_MISS]:
            cs[P.C_MISS], cs[P.C_TIME], cs[P.C_SPEED] = dist, t + s * dt, np.linalg.norm(v)
            cs[P.C_CLOSE_REL : P.C_CLOSE_REL + 3], cs[P.C_CLOSE_VEL : P.C_CLOSE_VEL + 3] = (
                closest,
                v,
            )
        closing = r0d < 0.0 or cs[P.C_ENDED_CLOSING] != 0.0
        cs[P.C_ENDED_CLOSING] = float(r1d < 0.0)
        outcome = P.OUTCOME_NONE
        if dist < P.PASS_RADIUS_M and closing and r1d > 0.0:
            outcome = P.OUTCOME_HIT if cs[P.C_MISS] <= cs[P.C_HIT_R] else P.OUTCOME_MISS
        elif (
            not np.isfinite(vx[: P.X_W + 3]).all()
            or not np.isfinite(r1).all()
            or v @ v > P.DIVERGED_SPEED_M_S**2
        ):
            outcome = P.OUTCOME_DIVERGED
        elif p[2] <= 0.0:
            outcome = P.OUTCOME_CRASHED
        if outcome != P.OUTCOME_NONE:
            cs[P.C_OUTCOME] = outcome
            return k - k0 + 1, buf
    return n, buf
