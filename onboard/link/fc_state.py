"""What the flight controller last said (:class:`FcState`) and the vehicle state a control
tick is handed from it (:func:`state_at`). Pure: no MAVLink here, so the simulator hands its
loop the state by the same code without importing pymavlink."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from ..constants import PX4_MAIN_OFFBOARD
from ..datatypes import VehicleState
from ..geometry import carried_attitude

MAX_PROPAGATION_S = 0.05  # an attitude older than this is carried forward no further
MAX_PROPAGATION_RATE_RAD_S = 35.0  # a gyro's full scale (2000 deg/s): beyond, not propagated
_CARRY_LIMITS = (MAX_PROPAGATION_S, MAX_PROPAGATION_RATE_RAD_S)


@dataclass
class FcState:
    """What the flight controller last said (ENU/FLU, onboard clock seconds)."""

    heartbeat_rx_s: float | None = None
    last_rx_s: float | None = None
    armed: bool = False
    custom_mode: int = 0
    pos_enu_m: np.ndarray | None = None
    vel_enu_m_s: np.ndarray | None = None
    q_wxyz: np.ndarray | None = None
    q_time_s: float | None = None  # when the attitude was sampled (PX4's stamp, our clock)
    rates_flu_rad_s: np.ndarray = field(default_factory=lambda: np.zeros(3))
    gyro_flu_rad_s: np.ndarray | None = None  # the latest HIGHRES_IMU gyro sample

    @property
    def offboard(self) -> bool:
        return ((self.custom_mode >> 16) & 0xFF) == PX4_MAIN_OFFBOARD


def state_at(fc: FcState, now_s: float) -> VehicleState:
    """The vehicle state for a control tick at ``now_s`` (position and velocity required):
    :func:`vehicle_state_at` of what the flight controller last said."""
    return vehicle_state_at(
        now_s,
        fc.pos_enu_m,
        fc.vel_enu_m_s,
        fc.q_wxyz,
        fc.q_time_s,
        fc.rates_flu_rad_s,
        fc.gyro_flu_rad_s,
    )


def vehicle_state_at(
    now_s: float,
    pos_enu_m: np.ndarray,
    vel_enu_m_s: np.ndarray,
    q_wxyz: np.ndarray | Sequence[float],
    q_time_s: float | None,
    rates_flu_rad_s: np.ndarray,
    gyro_flu_rad_s: np.ndarray | None,
) -> VehicleState:
    """The vehicle state for a control tick at ``now_s``: the attitude ``q_wxyz`` (sampled at
    ``q_time_s``, onboard clock s) propagated to the tick with the latest gyro rates
    ``gyro_flu_rad_s`` (the attitude's own rates ``rates_flu_rad_s`` before any HIGHRES_IMU),
    by at most ``MAX_PROPAGATION_S``, and not at all with rates beyond a gyro's full scale
    (the state's ``attitude_time_s`` says how far it got).
    The loop pairs it with an image estimate predicted to the tick, so an attitude left a
    stream period old would show as a line-of-sight error of rate x age. The simulator calls
    this directly (no :class:`FcState` to build each tick)."""
    q = q_wxyz
    q_at = None
    if q_time_s is not None and q is not None:
        rates = rates_flu_rad_s if gyro_flu_rad_s is None else gyro_flu_rad_s
        q = q.tolist() if type(q) is np.ndarray else q
        *q, q_at = carried_attitude(now_s, *q, q_time_s, *rates.tolist(), *_CARRY_LIMITS)
    if q is not None and type(q) is not np.ndarray:  # the simulator's floats
        q = np.array(q, dtype=float)
    return VehicleState(now_s, pos_enu_m, vel_enu_m_s, q, rates_flu_rad_s, q_at)
