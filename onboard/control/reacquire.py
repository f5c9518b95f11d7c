"""Track loss, re-acquisition and search (not in the paper; docs/core.md, "Track loss,
re-acquisition and search").

After the DKF's track goes stale (no accepted detection for ``PRG_TGT_LOST``) the loop walks
down a ladder, each rung bounded in time, and climbs back to tracking as soon as a detection
is accepted:

    tracking -> coast (the law on the DKF prediction, ``t_coast`` s while its 1 sigma is under
    ``coast_std`` px) -> reacquire (yaw toward the predicted LOS, fly toward it at ``v_reacq``,
    ``t_reacq`` s) -> search (``t_search`` s) -> lost (brake and hold: the failsafe)

and before the first detection: waiting (hold, ``t_wait`` s) -> search -> lost. The search
yaw-scans at hover at ``w_search``, or, when the vehicle was moving as it began (launched
toward a cue), flies the launch heading (the camera's, where the operator pointed it) at
``v_search``, weaving the camera ``weave_deg`` to each side of it.

Detections while the track is not live go through :class:`DetectionScreen` before the DKF
(which would start a new track on any detection once its own is stale): one within
``conf_deg`` plus 3 sigma of the prediction is fused at once; any other only after
``n_confirm`` consecutive detections agree with each other within ``conf_deg`` (also when the
prediction is vaguer than ``coast_std``: its gate would cover most of the image). A false blob
(clutter anywhere in the frame) therefore neither hijacks the track nor starts one.

Pure: every function is handed the times and states; no clock, no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..gains import Gains
from ..geometry import wrap_pi
from .guidance import saturate_norm


def angle_between_rad(a: np.ndarray, b: np.ndarray) -> float:
    """Angle (rad) between two unit vectors, accurate near 0 (atan2 of |a x b| and a . b)."""
    ax, ay, az = float(a[0]), float(a[1]), float(a[2])
    bx, by, bz = float(b[0]), float(b[1]), float(b[2])
    cx, cy, cz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
    return math.atan2(math.sqrt(cx * cx + cy * cy + cz * cz), ax * bx + ay * by + az * bz)


@dataclass(frozen=True, slots=True)
class Candidate:
    """A screened detection: its capture time (s) and its LOS at capture (unit, ENU)."""

    time_s: float
    los_enu: np.ndarray


class DetectionScreen:
    """Which detections may reach a stale (or absent) track. :meth:`offer` one detection at
    a time, in capture order, with its LOS; it answers the detections to fuse now, in capture
    order (empty while unconfirmed)."""

    def __init__(self) -> None:
        self._run: list[tuple[Any, Candidate]] = []  # consecutive mutually consistent ones
        self.rejected = 0  # offered and dropped (outvoted by a later run)

    def clear(self) -> None:
        self.rejected += len(self._run)
        self._run = []

    def offer(
        self,
        item: Any,
        cand: Candidate,
        pred_los_enu: np.ndarray | None,
        pred_sigma_rad: float,
        gains: Gains,
        sharp_sigma_rad: float = math.inf,
    ) -> list[Any]:
        """``item`` (a detection) with its LOS at capture; the prediction's LOS now and its
        1 sigma (rad), None without a track. A prediction vaguer than ``sharp_sigma_rad``
        confirms nothing by itself (its gate would cover the image)."""
        gate = math.radians(gains.conf_deg)
        near = (
            pred_los_enu is not None
            and pred_sigma_rad <= sharp_sigma_rad
            and angle_between_rad(cand.los_enu, pred_los_enu) <= gate + 3.0 * pred_sigma_rad
        )
        if near:
            self.clear()
            return [item]  # where the track said it would be
        if self._run and angle_between_rad(cand.los_enu, self._run[-1][1].los_enu) > gate:
            self.clear()  # inconsistent with the run so far: start a new one
        self._run.append((item, cand))
        if len(self._run) >= round(gains.n_confirm):
            out = [i for i, _ in self._run]
            self._run = []
            return out
        return []


VIEW_MARGIN_RAD = math.radians(5.0)  # inside the image's edge: a blob there is clipped
NO_VIEW_EDGES = (math.inf, -math.inf)  # every LOS counts as in view: no swing


def view_swing_m_s(
    los_enu: np.ndarray, fov_edges_rad: tuple[float, float], speed_m_s: float
) -> np.ndarray | None:
    """The velocity (m/s, ENU) that brings a LOS whose elevation lies beyond the level
    camera's top or bottom edge (``fov_edges_rad``, above body x, less VIEW_MARGIN_RAD) back
    into view: ``speed_m_s`` across the LOS in its vertical plane, toward the level (for a
    target below: down and away from it). The range is kept to first order, so the swing
    neither closes on a target it cannot see nor loses it; flying at the target's side
    instead would steepen the LOS further out of view. None when the LOS is in view."""
    x, y, z = (float(c) for c in los_enu)
    h = math.hypot(x, y)
    elev = math.atan2(z, h)
    top, bottom = fov_edges_rad
    if bottom + VIEW_MARGIN_RAD <= elev <= top - VIEW_MARGIN_RAD:
        return None
    s, c = math.sin(elev), math.cos(elev)
    hx, hy = (x / h, y / h) if h > 1e-9 else (0.0, 0.0)
    # d n / d elev = (-sin(elev) h, cos(elev)); moving along +-it turns the LOS by -+v/r
    k = math.copysign(speed_m_s, elev)
    return np.array((-k * s * hx, -k * s * hy, k * c))


def reacquire_accel(
    pred_los_enu: np.ndarray,
    velocity_enu_m_s: np.ndarray,
    gains: Gains,
    fov_edges_rad: tuple[float, float] = NO_VIEW_EDGES,
) -> np.ndarray:
    """Re-acquisition: the velocity loop a_d = k_brake (v_d - v), saturated to a_max, with
    v_d = v_reacq n_los, a slow flight toward the predicted LOS, or, when that LOS is beyond
    the level camera's top or bottom edge, :func:`view_swing_m_s` at v_reacq (m/s^2, ENU)."""
    v_d = view_swing_m_s(pred_los_enu, fov_edges_rad, gains.v_reacq)
    if v_d is None:
        v_d = gains.v_reacq * pred_los_enu
    return saturate_norm(gains.k_brake * (v_d - velocity_enu_m_s), gains.a_max)


def horizontal_unit(vec: np.ndarray) -> np.ndarray | None:
    """The horizontal direction of ``vec`` (unit, ENU), or None when it is nearly vertical."""
    x, y = float(vec[0]), float(vec[1])
    n = math.hypot(x, y)
    if n < 1e-6:
        return None
    return np.array([x / n, y / n, 0.0])


def search_accel(
    cue_enu: np.ndarray | None,
    velocity_enu_m_s: np.ndarray,
    gains: Gains,
    last_los_enu: np.ndarray | None = None,
    fov_edges_rad: tuple[float, float] = NO_VIEW_EDGES,
) -> np.ndarray:
    """Search: with a horizontal cue, hold that course at ``v_search`` and the altitude
    (a_d = k_brake (v_search cue - v)); without one, brake to a hover (a_d = -k_brake v), or,
    when the lost track's last estimate lies beyond the level camera's top or bottom edge
    (``last_los_enu``, the unit LOS from here to where it was), :func:`view_swing_m_s` at
    v_reacq until it is in view, so that the yaw scan sweeps across it: a target lost off the
    image's bottom edge is otherwise never back in view at hover; saturated to a_max (m/s^2,
    ENU)."""
    if cue_enu is not None:
        v_d = gains.v_search * cue_enu
    elif last_los_enu is not None:
        v_d = view_swing_m_s(last_los_enu, fov_edges_rad, gains.v_reacq)
    else:
        v_d = None
    if v_d is None:
        v_d = np.zeros(3)
    return saturate_norm(gains.k_brake * (v_d - velocity_enu_m_s), gains.a_max)


WEAVE_RAMP_PERIODS = 2.0  # weave periods over which its amplitude grows from 0


def search_yaw_rate(
    cue_enu: np.ndarray | None,
    camera_axis_enu: np.ndarray,
    direction: float,
    gains: Gains,
    search_time_s: float = 0.0,
) -> float:
    """Search yaw rate about body +z (rad/s): without a cue, scan at ``w_search`` in
    ``direction`` (+1 counter-clockwise seen from above, -1 clockwise); with one, weave the
    camera's heading about it, psi_d = psi_cue + A sin(2 pi t / T) (A = ``weave_deg``, T =
    ``t_weave``, t = ``search_time_s`` since the search began): the rate psi_d' plus k_R
    times the heading error, the latter capped at ``w_search``. The weave sweeps the
    camera's view A to each side of the course, so a target off the course is seen as it
    passes (and, turned toward it, nearer the image's centre in elevation too)."""
    if cue_enu is None:
        return math.copysign(gains.w_search, direction)
    axis = horizontal_unit(camera_axis_enu)
    if axis is None:
        return 0.0
    w = 2.0 * math.pi / gains.t_weave
    # the weave's amplitude grows over its first WEAVE_RAMP_PERIODS periods: the course
    # itself is flown first, where a target near it (the cue's likeliest place) comes into
    # view as the vehicle pitches down to accelerate, and the sweep widens the longer the
    # search lasts
    ramp_s = WEAVE_RAMP_PERIODS * gains.t_weave
    r = min(search_time_s / ramp_s, 1.0) if ramp_s > 0.0 else 1.0
    r_dot = 1.0 / ramp_s if r < 1.0 else 0.0
    amp = math.radians(gains.weave_deg)
    s, c = math.sin(w * search_time_s), math.cos(w * search_time_s)
    # headings as angles from +x (east) counter-clockwise: the rate about +z turns them
    err = wrap_pi(
        math.atan2(float(cue_enu[1]), float(cue_enu[0]))
        + amp * r * s
        - math.atan2(float(axis[1]), float(axis[0]))
    )
    correction = min(max(gains.k_R * err, -gains.w_search), gains.w_search)
    return amp * (r * w * c + r_dot * s) + correction


_FLOOR_TAU_S = 0.25  # the floor guard's velocity-loop time constant (about 2 / k_R)


def floor_guard_accel(
    accel_enu_m_s2: np.ndarray, height_m: float, vel_up_m_s: float, gains: Gains
) -> np.ndarray:
    """Ground clearance for the commands that fly without a live track (coast,
    re-acquisition, search): the vertical component of ``accel_enu_m_s2`` (m/s^2, ENU) is
    raised to at least a_z,min = (v_floor - v_up) / tau so that the descent rate never exceeds
    v_floor = -sqrt(2 (a_max / 2) h), h = ``height_m`` - ``h_floor`` the height above the
    floor (m): the vehicle can always stop at the floor with half of a_max; below it v_floor =
    -h / tau climbs back. a_z,min is capped at a_max and takes priority: the horizontal part
    shrinks to keep |a| <= a_max. A command that already satisfies it is returned unchanged
    (the same array)."""
    h = height_m - gains.h_floor
    # above: the braking curve sqrt(2 (a_max / 2) h); below: climb back
    v_floor = -math.sqrt(gains.a_max * h) if h > 0.0 else -h / _FLOOR_TAU_S
    a_z_min = min((v_floor - vel_up_m_s) / _FLOOR_TAU_S, gains.a_max)
    if not float(accel_enu_m_s2[2]) < a_z_min:
        return accel_enu_m_s2
    ax, ay = float(accel_enu_m_s2[0]), float(accel_enu_m_s2[1])
    room = math.sqrt(max(gains.a_max * gains.a_max - a_z_min * a_z_min, 0.0))
    n = math.hypot(ax, ay)
    if n > room:
        ax, ay = ax * room / n, ay * room / n
    return np.array([ax, ay, a_z_min])
