"""Re-started tracks of the delayed Kalman filter (:mod:`.dkf`).

Re-started tracks: a detection after the track went stale (``lost_timeout_s``) starts a new
track at its image point, but with ``carry_max_s`` > 0 (the loop's gain ``t_carry``) and the
old track last confirmed less than that long ago, the new one keeps what the old one still
knows: the target velocity with its covariance grown by the random walk over the time without
measurements (P_vv + q_v dt I: exactly what the propagation does to it), and, when the old
track is still propagated and the detection falls inside its grown image gate, the depth and
the depth-velocity covariance too, the detection's apparent size fused into them. A velocity
vaguer than the first-detection prior (``init_target_speed_m_s``) is not carried.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from .dkf_kernels import _TIME_EPS_S, _valid
from .dkf_values import _Meas, fresh_track

if TYPE_CHECKING:
    from .dkf import DelayedKalmanFilter


def carried_track(dkf: DelayedKalmanFilter, m: _Meas) -> tuple[tuple, np.ndarray] | None:
    """The state and covariance to restart ``dkf``'s track from at m (capture time m.t), keeping
    what the old track still knows (DESIGN.md §4; docs/core.md, "Track loss"), or None when it
    knows nothing useful. The image point is m's. The target velocity is the old track's,
    its covariance grown by the random walk over the time without measurements
    (P_vv + q_v dt I), if no component is vaguer than the first-detection prior. While the
    old track is still propagated and m falls inside its (grown) image gate, its depth
    and the depth-velocity covariance are kept too and m's apparent size is fused into
    them; otherwise the depth restarts from m's size (or the prior) as for a new track."""
    if m.t - dkf._last_accepted_s > dkf.carry_max_s:
        return None
    c = dkf.config
    s_v2 = c.init_target_speed_m_s**2
    j = dkf._index_at_or_before(m.t)
    x = P = None
    if dkf._initialised and dkf._HX[j]:
        P = dkf._covariance(j)
        x = dkf._X[j]
        if P is not None and m.t > dkf._T[j] + _TIME_EPS_S and j + 1 < dkf._hi:
            x, P = dkf._step(x, P, j + 1, m.t - float(dkf._T[j]))
        if P is None or not (_valid(x) and math.isfinite(float(P.trace()))):
            x = P = None
    if P is not None:
        if float(max(P[3, 3], P[4, 4], P[5, 5])) > s_v2:
            return None
        r = dkf._r_point
        y0, y1 = float(m.z[0] - x[0]), float(m.z[1] - x[1])
        s00, s01, s11 = float(P[0, 0]) + r, float(P[0, 1]), float(P[1, 1]) + r
        det = s00 * s11 - s01 * s01
        d2 = (s11 * y0 * y0 - 2.0 * s01 * y0 * y1 + s00 * y1 * y1) / det if det > 0 else 1e9
        if d2 <= dkf._gate2_point:
            # m where the old track predicted it: keep depth and velocity with their
            # covariance, reset the image point (variance 1, ~45 deg: uncorrelated) and
            # fuse m into it (the point, then its size against the carried depth)
            P0 = P.copy()
            P0[:2, :] = 0.0
            P0[:, :2] = 0.0
            P0[0, 0] = P0[1, 1] = 1.0
            x0, P0, ok = dkf._update(x.copy(), P0, m)
            return (x0, P0) if ok else None
        v, P_vv = x[3:].copy(), P[3:, 3:].copy()
    elif dkf._memory is not None:
        t0, v, P_vv = dkf._memory
        P_vv = P_vv + np.eye(3) * (dkf._q_v * max(m.t - t0, 0.0))
        if float(max(np.diag(P_vv))) > s_v2:
            return None
    else:
        return None
    x0, P0 = fresh_track(m, dkf.config, dkf._f)
    x0 = (*x0[:3], *v.tolist())
    P0[3:, 3:] = P_vv
    return x0, P0
