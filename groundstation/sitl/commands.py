"""MAVLink in, for :class:`.vehicle.SitlVehicle` (a mixin over its state): body-rate
setpoints (checked: finite, in range, OFFBOARD only while they stream), ``COMMAND_LONG``
(arm/disarm, TAKEOFF/LAND/RTL, DO_SET_MODE, REQUEST_MESSAGE, SET_MESSAGE_INTERVAL), PX4's
parameter protocol and ``TIMESYNC``, as PX4 answers them."""

from __future__ import annotations

import math
import time

from onboard.link.px4 import (
    AUTOPILOT_COMPONENT_ID,
    MODE_HOLD,
    MODE_OFFBOARD,
    PX4_MAIN_AUTO,
    PX4_MAIN_OFFBOARD,
    PX4_MAIN_POSCTL,
    PX4_SUB_AUTO_LOITER,
    VEHICLE_SYSTEM_ID,
    all_finite,
    frd_to_flu,
    mavlink,
    param_id_str,
    px4_mode_name,
)

from .autopilot import (
    MODE_LAND,
    MODE_RTL,
    MODE_TAKEOFF,
    PX4_SUB_AUTO_LAND,
    PX4_SUB_AUTO_RTL,
    PX4_SUB_AUTO_TAKEOFF,
    timesync_answer,
)

OFFBOARD_STREAM_S = 0.5  # a setpoint this recent is needed to enter offboard
MAX_RATE_CMD_RAD_S = 20.0


class SitlCommands:
    """The MAVLink-in half of :class:`.vehicle.SitlVehicle`."""

    def _handle(self, now: float) -> None:
        for msg in self.link.poll():
            kind = msg.get_type()
            try:
                if kind == "SET_ATTITUDE_TARGET":
                    self._setpoint(msg, now)
                elif kind == "TIMESYNC":
                    answer = timesync_answer(msg.tc1, msg.ts1, time.perf_counter() - self._t0)
                    if answer is not None:
                        self.link.send(self.link.mav.timesync_encode(*answer))
                elif (kind.startswith("PARAM_") or kind == "COMMAND_LONG") and self._for_us(msg):
                    if kind == "COMMAND_LONG":
                        self._command(msg, now)
                    else:
                        self._param(msg, kind)
            except (ValueError, TypeError, OverflowError, KeyError):
                self.link.bad_frames += 1  # a valid frame carrying nonsense (a NaN mode...)

    @staticmethod
    def _for_us(msg) -> bool:
        return msg.target_system in (VEHICLE_SYSTEM_ID, 0) and msg.target_component in (
            AUTOPILOT_COMPONENT_ID,
            0,
        )

    def _setpoint(self, msg, now: float) -> None:
        if msg.target_system != VEHICLE_SYSTEM_ID:
            return
        rates = (msg.body_roll_rate, msg.body_pitch_rate, msg.body_yaw_rate)
        ok = (
            msg.type_mask & mavlink.ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE
            and all_finite((*rates, msg.thrust))
            and 0.0 <= msg.thrust <= 1.0
            and all(abs(r) <= MAX_RATE_CMD_RAD_S for r in rates)
        )
        if not ok:
            self.rejected_setpoints += 1
            if self.rejected_setpoints == 1 or self.rejected_setpoints % 100 == 0:
                self._say(mavlink.MAV_SEVERITY_ERROR, "setpoint rejected: not finite/in range")
            return
        self.setpoints += 1
        self.setpoint = (frd_to_flu(rates), float(msg.thrust))
        self.last_setpoint_s = now
        self._queue_setpoint(now)

    def _ack(self, msg, result: int) -> None:
        """COMMAND_ACK addressed to whoever sent the command (PX4 fills the target too)."""
        self.link.send(
            self.link.mav.command_ack_encode(
                msg.command, result, 0, 0, msg.get_srcSystem(), msg.get_srcComponent()
            )
        )

    def _param(self, msg, kind: str) -> None:
        """PX4's parameter protocol on the autopilot component."""
        names = self.params.order
        if kind == "PARAM_REQUEST_LIST":
            for i in range(len(names)):
                self._send_param(i)
        elif kind == "PARAM_REQUEST_READ":
            name = param_id_str(msg.param_id)
            i = names.index(name) if msg.param_index < 0 and name in names else msg.param_index
            if 0 <= i < len(names):
                self._send_param(i)
        elif kind == "PARAM_SET":
            name = param_id_str(msg.param_id)
            if name not in self.params.specs:
                return  # PX4 does not answer an unknown name
            if not self.params.set_wire(name, float(msg.param_value), int(msg.param_type)):
                self._say(mavlink.MAV_SEVERITY_WARNING, f"param {name}: value refused")
            self._send_param(names.index(name))

    def _send_param(self, i: int) -> None:
        name = self.params.order[i]
        value, kind = self.params.wire(name)
        self.link.send(
            self.link.mav.param_value_encode(
                name.encode("ascii"), value, kind, len(self.params.order), i
            )
        )

    def _nav_command(self, msg, mode: int) -> None:
        """TAKEOFF (param7: altitude AMSL, NaN: MIS_TAKEOFF_ALT above home), LAND, RTL."""
        p = list(self.vehicle.p)
        if mode == MODE_TAKEOFF:
            if not self.armed or not self.landed:
                self._ack(msg, mavlink.MAV_RESULT_DENIED)
                why = "not armed" if not self.armed else "already flying"
                self._say(mavlink.MAV_SEVERITY_WARNING, f"takeoff refused: {why}")
                return
            alt = msg.param7 if msg.command == mavlink.MAV_CMD_NAV_TAKEOFF else math.nan
            rel = (
                self.params["MIS_TAKEOFF_ALT"]
                if not math.isfinite(alt)
                else alt - self.opt.home.alt_m
            )
            if not 0.5 <= rel <= 100.0:
                self._ack(msg, mavlink.MAV_RESULT_DENIED)
                return
            self._nav_goal = [p[0], p[1], rel]
        elif self.landed:
            self._ack(msg, mavlink.MAV_RESULT_DENIED)
            self._say(mavlink.MAV_SEVERITY_WARNING, "refused: landed")
            return
        elif mode == MODE_RTL:
            self._nav_goal = [0.0, 0.0, max(p[2], self.params["RTL_RETURN_ALT"])]
            self._rtl_phase = "climb"
        else:
            self._nav_goal = [p[0], p[1], 0.0]
        self.custom_mode = mode
        self.hold_p = p
        self._ack(msg, mavlink.MAV_RESULT_ACCEPTED)
        self._say(mavlink.MAV_SEVERITY_INFO, px4_mode_name(mode))

    def _request_message(self, msg) -> None:
        name = mavlink.mavlink_map.get(int(msg.param1))
        name = name.msgname if name is not None else None
        if name == "AUTOPILOT_VERSION":
            self._ack(msg, mavlink.MAV_RESULT_ACCEPTED)
            self._send_version()
        elif name in self.rates_hz:
            self._ack(msg, mavlink.MAV_RESULT_ACCEPTED)
            self._next_send[name] = 0.0  # sent at the next _send_due
        else:
            self._ack(msg, mavlink.MAV_RESULT_DENIED)

    def _command(self, msg, now: float) -> None:
        cmd = msg.command
        if cmd == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            if msg.param1 == 1.0:
                self.armed = True
                self._ack(msg, mavlink.MAV_RESULT_ACCEPTED)
            elif self.landed:
                self.armed = False
                self._ack(msg, mavlink.MAV_RESULT_ACCEPTED)
            else:
                self._ack(msg, mavlink.MAV_RESULT_DENIED)  # airborne: no disarm
                self._say(mavlink.MAV_SEVERITY_WARNING, "disarm refused: in air")
        elif cmd == mavlink.MAV_CMD_NAV_TAKEOFF:
            self._nav_command(msg, MODE_TAKEOFF)
        elif cmd == mavlink.MAV_CMD_NAV_LAND:
            self._nav_command(msg, MODE_LAND)
        elif cmd == mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            self._nav_command(msg, MODE_RTL)
        elif cmd == mavlink.MAV_CMD_REQUEST_MESSAGE:
            self._request_message(msg)
        elif cmd == mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
            self._ack(msg, mavlink.MAV_RESULT_ACCEPTED)
            self._send_version()
        elif cmd == mavlink.MAV_CMD_DO_SET_MODE:
            main, sub = int(msg.param2), int(msg.param3)
            nav = {PX4_SUB_AUTO_TAKEOFF: MODE_TAKEOFF, PX4_SUB_AUTO_LAND: MODE_LAND,
                   PX4_SUB_AUTO_RTL: MODE_RTL}  # fmt: skip
            if main == PX4_MAIN_AUTO and sub in nav:
                self._nav_command(msg, nav[sub])
                return
            if main == PX4_MAIN_OFFBOARD:
                if now - self.last_setpoint_s <= OFFBOARD_STREAM_S and self.armed:
                    if self.custom_mode != MODE_OFFBOARD:
                        self.custom_mode = MODE_OFFBOARD
                        if self.sortie_start_s is None:
                            self.sortie_start_s = self.time_s
                            self._rel = None
                        self._say(mavlink.MAV_SEVERITY_INFO, "OFFBOARD")
                    self._ack(msg, mavlink.MAV_RESULT_ACCEPTED)
                else:
                    self._ack(msg, mavlink.MAV_RESULT_DENIED)
                    self._say(mavlink.MAV_SEVERITY_WARNING, "offboard refused: no setpoints")
            elif main == PX4_MAIN_POSCTL or (
                main == PX4_MAIN_AUTO and sub in (0, PX4_SUB_AUTO_LOITER)
            ):
                if self.custom_mode != MODE_HOLD:
                    self._enter_hold("")
                self._ack(msg, mavlink.MAV_RESULT_ACCEPTED)
            else:
                self._ack(msg, mavlink.MAV_RESULT_UNSUPPORTED)
        elif cmd == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL:
            name = (
                mavlink.mavlink_map[int(msg.param1)].msgname
                if int(msg.param1) in mavlink.mavlink_map
                else None
            )
            if name in self.rates_hz and msg.param2 > 0:
                self.rates_hz[name] = min(1e6 / msg.param2, 500.0)
                self._ack(msg, mavlink.MAV_RESULT_ACCEPTED)
            else:
                self._ack(msg, mavlink.MAV_RESULT_DENIED)
        else:
            self._ack(msg, mavlink.MAV_RESULT_UNSUPPORTED)
