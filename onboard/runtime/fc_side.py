"""The flight controller's side of ``onboard run``: what PX4 sends (state, gyro, TIMESYNC,
parameters, acknowledgements) taken into :class:`FcState` and the loop, and what the runtime
sends it (the rate-and-thrust setpoint behind the output guard, stream and mode requests)."""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np

from ..datatypes import GyroSample
from ..link.fc_state import FcState
from ..link.frame_encoder import FrameEncoder
from ..link.params import ParamTable
from ..link.px4 import (
    AUTOPILOT_COMPONENT_ID,
    ONBOARD_COMPONENT_ID,
    TARGET_SYSTEM_ID,
    VEHICLE_SYSTEM_ID,
    MavLink,
    all_finite,
    frd_to_flu,
    mavlink,
    ned_to_enu,
    param_id_str,
    quat_ned_frd_to_enu_flu,
)
from ..link.timesync import TimesyncEstimator, on_timesync, send_request
from ..loop import InterceptionLoop
from .camera import Clock
from .px4_params import PX4_PARAMS_READ, check

MAX_RATE_RAD_S = 20.0
SET_ATTITUDE_TARGET = FrameEncoder(mavlink.MAVLink_set_attitude_target_message)
_NO_ATTITUDE = (1.0, 0.0, 0.0, 0.0)  # ignored (type mask): rates and thrust only
_RATES_ONLY = mavlink.ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE
STREAM_RATES_HZ = {
    mavlink.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: 200.0,
    mavlink.MAVLINK_MSG_ID_HIGHRES_IMU: 200.0,
    mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 100.0,
}

Event = Callable[[str, str], None]  # (severity, text)
Forward = Callable[..., None]  # (msg, now, always=False): passed through to the ground


def setpoint_fields(rates_flu, thrust: float, now_s: float) -> tuple | None:
    """SET_ATTITUDE_TARGET's fields in wire order for body rates ``rates_flu`` (FLU, rad/s,
    turned to PX4's FRD here) and normalised ``thrust`` at ``now_s`` (s; the message's boot
    time in ms), or None when the output guard refuses them: a rate beyond
    ``MAX_RATE_RAD_S``, a thrust outside [0, 1], NaN, an infinity or not numbers at all."""
    try:  # FLU -> FRD (frd_to_flu) on plain floats: the hot path allocates no arrays
        x, y, z = rates_flu.tolist() if type(rates_flu) is np.ndarray else rates_flu
        x, y, z, thrust = float(x), -float(y), -float(z), float(thrust)
    except (TypeError, ValueError):
        return None
    lim = MAX_RATE_RAD_S  # NaN and infinities fail each comparison
    if not (abs(x) <= lim and abs(y) <= lim and abs(z) <= lim and 0.0 <= thrust <= 1.0):
        return None
    return (
        int(now_s * 1000) & 0xFFFFFFFF, *_NO_ATTITUDE, x, y, z, thrust,
        VEHICLE_SYSTEM_ID, AUTOPILOT_COMPONENT_ID, _RATES_ONLY,
    )  # fmt: skip


class FlightControllerSide:
    """PX4's link: :meth:`take` each message it sends (under the runtime's loop lock), and the
    outputs. ``event`` reports (severity, text); ``forward`` passes a message to the ground."""

    def __init__(
        self, link: MavLink, params: ParamTable, clock: Clock, event: Event, forward: Forward
    ) -> None:
        self.link = link
        self.params = params
        self.clock = clock
        self.event = event
        self.forward = forward
        self.state = FcState()
        self.timesync = TimesyncEstimator()  # PX4's boot clock -> ours
        self.px4_params: dict[str, float] = {}  # what PX4 said (px4_params.PX4_PARAMS_READ)
        self.mode_requested = 0  # the custom mode last asked for, until acknowledged
        self.commands_sent = 0

    # ------------------------------------------------------------------ inputs
    def take(self, msg, now: float, loop: InterceptionLoop | None) -> None:
        """One message from the link at ``now`` (onboard clock s); gyro samples go to
        ``loop``."""
        f = self.state
        src_sys, src_comp = msg.get_srcSystem(), msg.get_srcComponent()
        kind = msg.get_type()
        if src_sys == TARGET_SYSTEM_ID:
            if kind in ("LOCAL_POSITION_NED", "HEARTBEAT"):
                self.forward(msg, now)
            return
        if src_sys != VEHICLE_SYSTEM_ID or src_comp != AUTOPILOT_COMPONENT_ID:
            return
        f.last_rx_s = now
        if kind == "HEARTBEAT":
            f.heartbeat_rx_s = now
            f.armed = bool(msg.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
            f.custom_mode = int(msg.custom_mode)
            self.forward(msg, now, always=True)
        elif kind == "ATTITUDE_QUATERNION":
            q = (msg.q1, msg.q2, msg.q3, msg.q4)
            rates = (msg.rollspeed, msg.pitchspeed, msg.yawspeed)
            if all_finite(q + rates) and abs(math.fsum(c * c for c in q) - 1.0) < 0.1:
                f.q_wxyz = quat_ned_frd_to_enu_flu(q)
                f.rates_flu_rad_s = frd_to_flu(rates)
                f.q_time_s = self._fc_time(msg.time_boot_ms * 1e-3, now, self._arrival_s(msg, now))
                self.forward(msg, now)
        elif kind == "LOCAL_POSITION_NED":
            p, v = (msg.x, msg.y, msg.z), (msg.vx, msg.vy, msg.vz)
            if all_finite(p + v):
                f.pos_enu_m, f.vel_enu_m_s = ned_to_enu(p), ned_to_enu(v)
                self.forward(msg, now)
        elif kind == "HIGHRES_IMU":
            g = (msg.xgyro, msg.ygyro, msg.zgyro)
            if all_finite(g):
                f.gyro_flu_rad_s = frd_to_flu(g)
                if loop is not None:
                    t = self._fc_time(msg.time_usec * 1e-6, now)
                    loop.on_gyro(GyroSample(t, f.gyro_flu_rad_s))
        elif kind == "TIMESYNC":
            on_timesync(self.link, self.timesync, msg, self._arrival_s(msg, now))
        elif kind == "PARAM_VALUE" and param_id_str(msg.param_id) in PX4_PARAMS_READ:
            name, g = param_id_str(msg.param_id), self.params.gains
            said = check(name, float(msg.param_value), self.params.runtime.HOVER_THR, g.v_max)
            self.px4_params[name] = float(msg.param_value)
            if said is not None:
                self.event(*said)
        elif kind == "STATUSTEXT":
            self.forward(msg, now, always=True)
        elif kind == "COMMAND_ACK":
            if msg.target_component not in (0, ONBOARD_COMPONENT_ID):
                return  # an answer to somebody else on the link
            if msg.command == mavlink.MAV_CMD_DO_SET_MODE and self.mode_requested:
                if msg.result == mavlink.MAV_RESULT_ACCEPTED:
                    f.custom_mode = self.mode_requested  # the next heartbeat confirms
                self.mode_requested = 0
            if msg.result != mavlink.MAV_RESULT_ACCEPTED:
                self.event("warning", f"PX4 refused command {msg.command} ({msg.result})")

    def _arrival_s(self, msg, now: float) -> float:
        """When a frame reached us (the kernel's UDP timestamp when there is one)."""
        rx = getattr(msg, "rx_monotonic_s", None)
        return now if rx is None else self.clock.now() - (time.monotonic() - rx)

    def _fc_time(self, t_fc_s: float, now: float, arrival: float | None = None) -> float:
        """A flight-controller sample time in our clock (TIMESYNC), else its arrival
        (``arrival``, or ``now``)."""
        t = self.timesync.to_companion(t_fc_s)
        if t is None or not now - 0.5 <= t <= now + 0.002:
            return now if arrival is None else arrival
        return min(t, now)

    # ------------------------------------------------------------------ outputs
    def send_command(self, rates_flu: np.ndarray, thrust: float, now: float) -> bool:
        """The rate-and-thrust setpoint; a refused one (output guard) is replaced by level
        hover at the configured hover thrust."""
        fields = setpoint_fields(rates_flu, thrust, now)
        if fields is None:  # the last line of defence: nothing non-finite or wild reaches PX4
            self.event("error", "output guard: bad command replaced by hover")
            fields = setpoint_fields((0.0, 0.0, 0.0), float(self.params.runtime.HOVER_THR), now)
        sent = self.link.send_fields(SET_ATTITUDE_TARGET, *fields)
        if sent:
            self.commands_sent += 1
        return sent

    def request_streams(self) -> None:
        """Ask PX4 for the state at the rates the loop needs (MAV_CMD_SET_MESSAGE_INTERVAL)
        and for the parameters we depend on (px4_params.py)."""
        for msg_id, hz in STREAM_RATES_HZ.items():
            self.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, 1e6 / hz)
        for name in PX4_PARAMS_READ:
            self.link.send(self.link.mav.param_request_read_encode(VEHICLE_SYSTEM_ID,
                           AUTOPILOT_COMPONENT_ID, name.encode(), -1))  # fmt: skip

    def command(self, command: int, *params: float) -> None:
        """COMMAND_LONG to the autopilot."""
        p = list(params) + [0.0] * (7 - len(params))
        self.link.send(
            self.link.mav.command_long_encode(
                VEHICLE_SYSTEM_ID, AUTOPILOT_COMPONENT_ID, command, 0, *p
            )
        )

    def timesync_request(self) -> None:
        send_request(self.link, self.clock.now())  # stamped as it goes out
