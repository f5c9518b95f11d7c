"""The state-estimate model's kernels (:mod:`.estimate`) written as the model is stated (its
module docstring): Gauss-Markov and random-walk error processes, a delay line interpolating
the truth, the estimate handed to the loop. Vectors are numpy arrays; quaternions (w, x, y, z).
The specification the compiled kernels are checked against (tests/test_kernel_references.py)."""

from __future__ import annotations

import math

import numpy as np

from onboard.geometry_reference import carried_attitude, quaternion_exp, quaternion_product

from . import estimate as E  # noqa: N812
from . import physics as P  # noqa: N812
from .physics_reference import gyro_mean


def advance_errors(t: float, k: np.ndarray, x: np.ndarray, normals: np.ndarray) -> tuple:
    """Each error process stepped exactly to t (once per distinct time): the Gauss-Markov ones
    (position, velocity, attitude) x <- a x + sigma sqrt(1 - a^2) n with a = exp(-dt / tau),
    the gyro bias x <- x + walk sqrt(dt) n; each with the next row of its own normals.
    Returns the new (k, x)."""
    k, x = k.copy(), x.copy()
    last = k[E.K_T]
    if not math.isnan(last):
        dt = t - last
        if dt <= 0.0:
            return k, x
        i = int(k[E.K_ROW])
        for p in range(3):
            a = math.exp(-dt / k[E.K_TAU + p])
            x[p] = a * x[p] + k[E.K_SIGMA + p] * math.sqrt(1.0 - a * a) * normals[p, i]
        x[E.E_BIAS] = x[E.E_BIAS] + k[E.K_WALK] * math.sqrt(dt) * normals[E.E_BIAS, i]
        k[E.K_ROW] = i + 1
    k[E.K_T] = t
    return k, x


def delayed(samples: list[np.ndarray], lag_s: float, now_s: float) -> np.ndarray:
    """The truth ``lag_s`` before ``now_s`` from the samples held (time, p, v, q, w; oldest
    first): linear between the two around it (the quaternion on the short way, normalised),
    the oldest while the history does not reach back that far."""
    tq = now_s - lag_s
    a = samples[0]
    if len(samples) == 1 or tq <= a[0] + 1e-12:
        return a.copy()
    b = samples[1].copy()
    f = (tq - a[0]) / (b[0] - a[0])
    if not float(a[7:11] @ b[7:11]) >= 0.0:
        b[7:11] = -b[7:11]
    out = a + f * (b - a)
    out[0] = tq
    out[7:11] /= np.linalg.norm(out[7:11])
    return out


def delay_push(ring: np.ndarray, now: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Push ``now`` into the delay line (ring layout of :class:`~.estimate.DelayLine`), drop
    the samples no longer needed (those before the one at or before now - lag), and read the
    delayed truth. Returns (the new ring, the delayed sample)."""
    ring = ring.copy()
    cap = ring.shape[0] - 1
    lo, n, lag = int(ring[0, 0]), int(ring[0, 1]), ring[0, 2]
    ring[1 + (lo + n) % cap] = now
    n += 1
    while n >= 2 and ring[1 + (lo + 1) % cap, 0] <= now[0] - lag + 1e-12:
        lo, n = (lo + 1) % cap, n - 1
    ring[0, 0], ring[0, 1] = lo, n
    held = [ring[1 + (lo + i) % cap] for i in range(n)]
    return ring, delayed(held, lag, now[0])


def estimate_of(
    k: np.ndarray, x: np.ndarray, ring: np.ndarray, att_ring: np.ndarray, now: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The estimate of the truth ``now``: position and velocity ``lag`` old plus their
    errors; attitude ``att_lag`` old times exp(attitude error) (no renormalising); body rates
    ``att_lag`` old plus the gyro bias. Returns (rings, the 13 floats)."""
    ring, old = delay_push(ring, now)
    att_ring, att_old = delay_push(att_ring, now)
    p = old[1:4] + x[E.E_POS]
    v = old[4:7] + x[E.E_VEL]
    q = quaternion_product(att_old[7:11], quaternion_exp(x[E.E_ATT]))
    w = att_old[11:14] + x[E.E_BIAS]
    return ring, att_ring, np.concatenate([p, v, q, w])


def hand_off(
    t: float,
    truth: np.ndarray,
    noise: np.ndarray,
    sigma: float,
    k: np.ndarray,
    x: np.ndarray,
    normals: np.ndarray,
    ring: np.ndarray,
    att_ring: np.ndarray,
) -> np.ndarray:
    """A control tick's inputs from the vehicle's true state: the gyro sample (the mean rate
    since the last tick plus white noise sigma n plus the bias), the estimate
    (:func:`estimate_of`) with its attitude carried to the tick from its stamp ``att_lag``
    before it at the gyro's rates (:func:`~onboard.geometry_reference.carried_attitude`), and
    the time that attitude is of (17 floats)."""
    rate = gyro_mean(truth) + noise * sigma
    k, x = advance_errors(t, k, x, normals)
    gyro = rate + x[E.E_BIAS]
    now = np.concatenate([[t], truth[P.X_P : P.X_P + 13]])
    _, _, est = estimate_of(k, x, ring, att_ring, now)
    q, q_at = carried_attitude(
        t, est[6:10], t - k[E.K_ATT_LAG], gyro, k[E.K_MAX_DT], k[E.K_MAX_RATE]
    )
    est[6:10] = q
    return np.concatenate([gyro, est, [q_at]])
