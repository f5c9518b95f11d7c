"""``groundstation sitl``: the simulator as a PX4-like quadrotor on a MAVLink link.

It advances the same vehicle, target and wind models as the simulator in real time and
behaves as PX4 does towards an offboard computer:

- ``HEARTBEAT`` as a PX4 quadrotor (custom mode: main mode << 16 | sub mode << 24), armed
  and airborne in HOLD (AUTO_LOITER) at the scenario's start position, or (``on_ground``)
  disarmed and landed below it;
- ``ATTITUDE_QUATERNION`` and ``HIGHRES_IMU`` at 200 Hz, ``LOCAL_POSITION_NED`` at 100 Hz
  (NED/FRD, converted by :mod:`onboard.link.px4`); ``GLOBAL_POSITION_INT`` (around a
  configurable home), ``EXTENDED_SYS_STATE`` (landed state), ``SYS_STATUS`` (healthy sensor
  bits, battery) and ``BATTERY_STATUS``, ``HOME_POSITION``; ``MAV_CMD_REQUEST_MESSAGE``;
- arm/disarm (on the ground), ``MAV_CMD_NAV_TAKEOFF``, ``_LAND`` and ``_RETURN_TO_LAUNCH``
  (PX4's AUTO sub-modes, flown by the hold controller at PX4's speeds);
- PX4's parameters the vehicle honours or reports (:mod:`.autopilot`) over the parameter
  protocol, and ``TIMESYNC`` answered on the vehicle's boot clock;
- ``SET_ATTITUDE_TARGET`` (body rates + thrust, attitude ignored) accepted in OFFBOARD;
  ``MAV_CMD_DO_SET_MODE`` to OFFBOARD only while setpoints stream (PX4's rule); offboard
  loss (no setpoint for ``offboard_loss_s``) falls back to HOLD;
- the target reports itself as system 2 (``HEARTBEAT`` and ``LOCAL_POSITION_NED``), as a
  cooperative target drone would, so the ground station can draw it;
- the camera's rendered frames go to the onboard computer over :class:`CameraServer`,
  each sent once the scenario's camera delay has passed.

The target starts moving, and the sortie clock starts, when the vehicle first enters
offboard; the closest approach is then tracked in continuous time, and the result printed as
one ``SITL_RESULT {json}`` line when the vehicle passes the target.
"""

from __future__ import annotations

import heapq
import json
import math
import select
import sys
import threading
import time
from dataclasses import dataclass, field

import numpy as np

from onboard.camera_model import CameraModel
from onboard.control.attitude import attitude_command
from onboard.enums import Outcome
from onboard.gains import Gains
from onboard.geometry import quat_to_rotmat, wrap_pi
from onboard.link.px4 import (
    AUTOPILOT_COMPONENT_ID,
    MODE_HOLD,
    MODE_OFFBOARD,
    PX4_MAIN_AUTO,
    PX4_MAIN_OFFBOARD,
    PX4_MAIN_POSCTL,
    PX4_SUB_AUTO_LOITER,
    TARGET_SYSTEM_ID,
    VEHICLE_SYSTEM_ID,
    MavLink,
    all_finite,
    enu_to_ned,
    flu_to_frd,
    frd_to_flu,
    mavlink,
    param_id_str,
    px4_custom_mode,
    px4_mode_name,
    quat_enu_flu_to_ned_frd,
)

from ..scenario import Scenario
from ..sim.render import FrameRenderer
from ..sim.simulation import PASS_RADIUS_M, closest_in_step
from ..sim.targets import Target
from ..sim.vehicle import Multicopter
from ..sim.wind import Wind
from .autopilot import (
    SENSORS_HEALTHY,
    AutopilotParams,
    Battery,
    Home,
    timesync_answer,
)
from .camera_server import CameraServer

PHYSICS_HZ = 600
RATES_HZ = {
    "ATTITUDE_QUATERNION": 200.0,
    "HIGHRES_IMU": 200.0,
    "LOCAL_POSITION_NED": 100.0,
    "GLOBAL_POSITION_INT": 50.0,
    "EXTENDED_SYS_STATE": 5.0,
    "SYS_STATUS": 2.0,
    "BATTERY_STATUS": 2.0,
    "HOME_POSITION": 1.0,
}
PX4_SUB_AUTO_TAKEOFF, PX4_SUB_AUTO_RTL, PX4_SUB_AUTO_LAND = 2, 5, 6
MODE_TAKEOFF = px4_custom_mode(PX4_MAIN_AUTO, PX4_SUB_AUTO_TAKEOFF)
MODE_LAND = px4_custom_mode(PX4_MAIN_AUTO, PX4_SUB_AUTO_LAND)
MODE_RTL = px4_custom_mode(PX4_MAIN_AUTO, PX4_SUB_AUTO_RTL)
RTL_CRUISE_M_S = 5.0  # PX4's MPC_XY_CRUISE
TARGET_POSITION_HZ = 20.0
OFFBOARD_STREAM_S = 0.5  # a setpoint this recent is needed to enter offboard
MAX_RATE_CMD_RAD_S = 20.0


@dataclass
class SitlOptions:
    offboard_loss_s: float = 1.0  # PX4 COM_OF_LOSS_T (a parameter: PARAM_SET changes it)
    camera_blackout_after_s: float | None = None  # fault injection: no frames after this
    seed: int = 0
    home: Home = field(
        default_factory=Home
    )  # where local (0, 0, 0) is: GLOBAL_POSITION_INT, HOME_POSITION
    on_ground: bool = False  # start disarmed and landed below the scenario's start position


class SitlVehicle:
    def __init__(
        self,
        scenario: Scenario,
        link: MavLink,
        camera: CameraServer,
        options: SitlOptions | None = None,
        out=None,
    ) -> None:
        self.scenario = scenario
        self.link = link
        self.camera = camera
        self.opt = options or SitlOptions()
        self.out = out or sys.stdout
        ss = np.random.SeedSequence(self.opt.seed)
        cam_rng, wind_rng, gyro_rng, render_rng = (np.random.default_rng(s) for s in ss.spawn(4))
        self._cam_rng, self._gyro_rng = cam_rng, gyro_rng
        c = scenario.camera
        self.camera_model = CameraModel(
            c.width_px, c.height_px, c.hfov_deg, c.mount_pitch_deg, c.mount_roll_deg
        )
        self.renderer = FrameRenderer(self.camera_model, render_rng)
        self.vehicle = Multicopter(scenario.interceptor)
        self.vehicle.v = [0.0, 0.0, 0.0]  # PX4 holds position before offboard
        ic = scenario.interceptor
        hover = min(max(1.0 / ic.thrust_to_weight, 0.1), 0.8)
        self.params = AutopilotParams(COM_OF_LOSS_T=self.opt.offboard_loss_s, MPC_THR_HOVER=hover)
        self.battery = Battery(int(self.params["BAT1_N_CELLS"]), self.params["BAT1_CAPACITY"])
        self.landed = self.opt.on_ground
        self._landed_at_s: float | None = None  # touchdown after a flight (auto-disarm)
        self._nav_goal: list[float] | None = None  # TAKEOFF / LAND / RTL target (ENU)
        self._rtl_phase = ""
        if self.landed:
            self.vehicle.p[2] = 0.0
        self.target = Target(scenario.target)
        self.wind = Wind(scenario.wind, wind_rng, scenario.target.position_m)
        self.target.settle_in_wind(self.wind.mean_at)
        self.dt_s = 1.0 / PHYSICS_HZ
        self.step_index = 0
        self.armed = not self.opt.on_ground
        self.custom_mode = MODE_HOLD
        self.hold_p = list(self.vehicle.p)
        self.hold_yaw = self._yaw()
        self.setpoint: tuple[np.ndarray, float] | None = None
        self.last_setpoint_s = -1e9
        self.setpoints = 0
        self.rejected_setpoints = 0
        self.sortie_start_s: float | None = None
        self.miss_m = math.inf
        self.closest = None
        self.result: dict | None = None
        self._rel = None
        self._frames: list = []  # (send time, n, capture time, image)
        self._n = 0
        self.rates_hz = dict(RATES_HZ)  # MAV_CMD_SET_MESSAGE_INTERVAL changes these
        self._next_send = {k: 0.0 for k in RATES_HZ}
        self._next_target_s = 0.0
        self._next_hb_s = 0.0
        self.hit_radius_m = 0.5 * (scenario.target.diameter_m + scenario.interceptor.size_m)
        self._cam_div = round(PHYSICS_HZ / c.rate_hz)
        self._hold_div = 3  # the hold controller runs at 200 Hz
        self._gains = Gains()
        self._stop = threading.Event()
        self.max_speed_m_s = 0.0
        self._t0 = time.perf_counter()  # the boot clock (TIMESYNC, time_boot_ms)
        self._extra_senders = self._senders()

    # ------------------------------------------------------------------ helpers
    @property
    def time_s(self) -> float:
        return self.step_index * self.dt_s

    @property
    def sortie_time_s(self) -> float:
        return 0.0 if self.sortie_start_s is None else self.time_s - self.sortie_start_s

    def _yaw(self) -> float:
        R = quat_to_rotmat(self.vehicle.q)
        return math.atan2(R[1, 0], R[0, 0])

    def _say(self, severity: int, text: str) -> None:
        self.link.statustext(severity, text)
        print(f"[sitl {self.time_s:8.3f}] {text}", file=self.out, flush=True)

    def _enter_hold(self, why: str) -> None:
        self.custom_mode = MODE_HOLD
        self._nav_goal = None
        self.hold_p = list(self.vehicle.p)
        self.hold_yaw = self._yaw()
        self._say(
            mavlink.MAV_SEVERITY_WARNING if why else mavlink.MAV_SEVERITY_INFO,
            f"HOLD{': ' + why if why else ''}",
        )

    # ------------------------------------------------------------------ PX4's hold and AUTO
    def _nav(self, dt: float) -> None:
        """TAKEOFF, LAND and RTL: move the hold point toward the goal at PX4's speeds."""
        goal, hp, prm = self._nav_goal, self.hold_p, self.params
        if goal is None:
            return
        mode = self.custom_mode
        if mode == MODE_RTL and self._rtl_phase == "climb":
            hp[2] = min(hp[2] + prm["MPC_Z_VEL_MAX_UP"] * dt, goal[2])
            if self.vehicle.p[2] >= goal[2] - 0.3:
                self._rtl_phase = "return"
        elif mode == MODE_RTL and self._rtl_phase == "return":
            d = np.array(goal[:2]) - np.array(hp[:2])
            n = float(np.linalg.norm(d))
            step = min(RTL_CRUISE_M_S, prm["MPC_XY_VEL_MAX"]) * dt
            if n <= step:
                hp[0], hp[1] = goal[0], goal[1]
            else:
                hp[0], hp[1] = hp[0] + d[0] * step / n, hp[1] + d[1] * step / n
            p = self.vehicle.p
            if math.hypot(goal[0] - p[0], goal[1] - p[1]) < 0.5:
                self._rtl_phase = "land"
        elif mode == MODE_TAKEOFF:
            hp[2] = min(hp[2] + prm["MPC_TKO_SPEED"] * dt, goal[2])
            if self.vehicle.p[2] >= goal[2] - 0.1:
                self._enter_hold("")
                self._say(mavlink.MAV_SEVERITY_INFO, "Takeoff complete")
        if mode == MODE_LAND or (mode == MODE_RTL and self._rtl_phase == "land"):
            hp[2] = max(hp[2] - prm["MPC_LAND_SPEED"] * dt, -1.0)  # into the ground

    def _hold_command(self) -> None:
        v = self.vehicle
        p, vel = np.array(v.p), np.array(v.v)
        a = 1.2 * (np.array(self.hold_p) - p) - 2.0 * vel
        n = float(np.linalg.norm(a))
        if n > 4.0:
            a *= 4.0 / n
        yaw_rate = 1.5 * wrap_pi(self.hold_yaw - self._yaw())
        w, thrust = attitude_command(a, quat_to_rotmat(v.q), yaw_rate, self._gains, v.params)
        v.command(w, thrust)

    @property
    def landed_state(self) -> int:
        """MAV_LANDED_STATE, as EXTENDED_SYS_STATE reports it."""
        if self.landed:
            return mavlink.MAV_LANDED_STATE_ON_GROUND
        if self.custom_mode == MODE_TAKEOFF:
            return mavlink.MAV_LANDED_STATE_TAKEOFF
        if self.custom_mode == MODE_LAND or (
            self.custom_mode == MODE_RTL and self._rtl_phase == "land"
        ):
            return mavlink.MAV_LANDED_STATE_LANDING
        return mavlink.MAV_LANDED_STATE_IN_AIR

    def _on_ground(self, t: float) -> bool:
        """Landed: nothing moves until armed and asked up (TAKEOFF, or offboard thrust above
        hover); PX4 disarms COM_DISARM_LAND seconds after a touchdown."""
        veh = self.vehicle
        if self.armed and (
            self.custom_mode == MODE_TAKEOFF
            or (
                self.custom_mode == MODE_OFFBOARD
                and self.setpoint is not None
                and self.setpoint[1] > self.params["MPC_THR_HOVER"] + 0.02
            )
        ):
            self.landed, self._landed_at_s = False, None
            return False
        veh.v, veh.w, veh.p[2] = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], 0.0
        veh.thrust_n = veh.cmd_thrust_n = 0.0
        delay = self.params["COM_DISARM_LAND"]
        if self.armed and self._landed_at_s is not None and 0 <= delay <= t - self._landed_at_s:
            self.armed = False
            self._landed_at_s = None
            self._say(mavlink.MAV_SEVERITY_INFO, "Disarmed by landing")
        return True

    def _touchdown(self, t: float) -> None:
        veh = self.vehicle
        veh.p[2], veh.v = 0.0, [0.0, 0.0, 0.0]
        self.landed, self._landed_at_s = True, t
        if self.custom_mode in (MODE_LAND, MODE_RTL):
            self.custom_mode, self._nav_goal = MODE_HOLD, None
            self.hold_p = list(veh.p)
        self._say(mavlink.MAV_SEVERITY_INFO, "Landing detected")

    # ------------------------------------------------------------------ physics
    def step(self) -> None:
        k = self.step_index
        t = k * self.dt_s
        veh = self.vehicle
        if k % self._cam_div == 0:
            self._capture(t)
        if self.custom_mode == MODE_OFFBOARD:
            if t - self.last_setpoint_s > self.params["COM_OF_LOSS_T"]:
                self._enter_hold("offboard loss: no setpoints")
            elif self.setpoint is not None:
                veh.command(*self.setpoint)
        if self.custom_mode != MODE_OFFBOARD and k % self._hold_div == 0:
            self._nav(self._hold_div * self.dt_s)
            self._hold_command()
        wind = self.wind  # evaluated where each body is
        hover_n = self.params["MPC_THR_HOVER"] * veh.params.max_thrust_n
        if self.landed and self._on_ground(t):
            self.battery.step(self.dt_s, self.armed, 0.0)
        else:
            veh.step(self.dt_s, wind.at(veh.p))
            self.battery.step(self.dt_s, self.armed, veh.thrust_n / hover_n)
        if self.sortie_start_s is not None:
            ts = t - self.sortie_start_s
            self.target.advance(ts + self.dt_s, self.dt_s, wind.at(self.target.p))
            self._track_closest(ts)
        if veh.p[2] <= 0.0 and not self.landed and veh.v[2] <= 0.0:
            self._touchdown(t)
        self.wind.step(self.dt_s)
        self.step_index = k + 1

    def _track_closest(self, ts: float) -> None:
        tp, vp = self.target.p, self.vehicle.p
        r1 = [tp[0] - vp[0], tp[1] - vp[1], tp[2] - vp[2]]
        r0, self._rel = self._rel, r1
        v = self.vehicle.v
        speed = math.sqrt(v[0] ** 2 + v[1] ** 2 + v[2] ** 2)
        self.max_speed_m_s = max(self.max_speed_m_s, speed)
        if r0 is None or self.result is not None:
            return
        dist, s, _, closing, opening = closest_in_step(r0, r1)
        if dist < self.miss_m:
            self.miss_m = dist
            self.closest = (ts + s * self.dt_s, speed)
        if closing and opening and dist < PASS_RADIUS_M:
            hit = self.miss_m <= self.hit_radius_m
            self._finish((Outcome.HIT if hit else Outcome.MISS).value)
        elif vp[2] <= 0.0:
            self._finish(Outcome.CRASHED.value)

    def _finish(self, outcome: str) -> None:
        t_c, speed = self.closest or (self.sortie_time_s, 0.0)
        self.result = {
            "outcome": outcome,
            "miss_m": round(self.miss_m, 4),
            "intercept_time_s": round(t_c, 3),
            "terminal_speed_m_s": round(speed, 3),
            "max_speed_m_s": round(self.max_speed_m_s, 3),
            "scenario": self.scenario.name,
            "hit_radius_m": self.hit_radius_m,
            "setpoints": self.setpoints,
            "rejected_setpoints": self.rejected_setpoints,
        }
        self._say(mavlink.MAV_SEVERITY_INFO, f"{outcome}: miss {self.miss_m:.3f} m")
        print("SITL_RESULT " + json.dumps(self.result), file=self.out, flush=True)

    def _capture(self, t: float) -> None:
        blackout = self.opt.camera_blackout_after_s
        if (
            blackout is not None
            and self.sortie_start_s is not None
            and (self.sortie_time_s >= blackout)
        ):
            return
        spec = self.scenario.camera
        rng = self._cam_rng
        dropped = rng.random() < spec.dropout_probability
        delay = spec.delay_s + spec.delay_jitter_s * float(rng.standard_normal())
        delay = min(max(delay, 0.5 * spec.delay_s), 2.0 * spec.delay_s + 1e-9)
        if dropped or self.camera.clients == 0:
            return
        R_WC = quat_to_rotmat(self.vehicle.q) @ self.camera_model.R_BC
        frame = self.renderer.render(
            R_WC, np.array(self.vehicle.p), np.array(self.target.p), self.scenario.target.diameter_m
        )
        self._n += 1
        heapq.heappush(self._frames, (t + delay, self._n, t, frame))

    # ------------------------------------------------------------------ MAVLink in
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

    # ------------------------------------------------------------------ MAVLink out
    def _send_due(self, now: float) -> None:
        link, mav, veh = self.link, self.link.mav, self.vehicle
        boot_ms = int(now * 1000) & 0xFFFFFFFF
        if now >= self._next_hb_s:
            self._next_hb_s = now + 1.0
            base = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
            if self.armed:
                base |= mavlink.MAV_MODE_FLAG_SAFETY_ARMED
            link.heartbeat(
                mavlink.MAV_TYPE_QUADROTOR,
                mavlink.MAV_AUTOPILOT_PX4,
                base,
                self.custom_mode,
                mavlink.MAV_STATE_ACTIVE if self.armed else mavlink.MAV_STATE_STANDBY,
            )
            self._as_target(
                lambda: link.heartbeat(
                    mavlink.MAV_TYPE_FREE_BALLOON,
                    mavlink.MAV_AUTOPILOT_INVALID,
                    0,
                    0,
                    mavlink.MAV_STATE_ACTIVE,
                )
            )
        due = self._next_send
        if now >= due["ATTITUDE_QUATERNION"]:
            due["ATTITUDE_QUATERNION"] = now + 1.0 / self.rates_hz["ATTITUDE_QUATERNION"]
            q = quat_enu_flu_to_ned_frd(veh.q)
            w = flu_to_frd(veh.w)
            link.send(
                mav.attitude_quaternion_encode(
                    boot_ms, *(float(c) for c in q), float(w[0]), float(w[1]), float(w[2])
                )
            )
        if now >= due["HIGHRES_IMU"]:
            due["HIGHRES_IMU"] = now + 1.0 / self.rates_hz["HIGHRES_IMU"]
            noise = self._gyro_rng.standard_normal(3) * self.scenario.sim.gyro_noise_rad_s
            g = flu_to_frd(np.array(veh.read_gyro()) + noise)
            R = quat_to_rotmat(veh.q)
            f_flu = R.T @ (np.array(veh.accel) + np.array([0.0, 0.0, 9.81]))
            f = flu_to_frd(f_flu)
            link.send(
                mav.highres_imu_encode(
                    int(now * 1e6),
                    float(f[0]),
                    float(f[1]),
                    float(f[2]),
                    float(g[0]),
                    float(g[1]),
                    float(g[2]),
                    0.0,
                    0.0,
                    0.0,
                    1013.0,
                    0.0,
                    float(veh.p[2]),
                    20.0,
                    0b1111111,
                )
            )
        if now >= due["LOCAL_POSITION_NED"]:
            due["LOCAL_POSITION_NED"] = now + 1.0 / self.rates_hz["LOCAL_POSITION_NED"]
            p, v = enu_to_ned(veh.p), enu_to_ned(veh.v)
            link.send(mav.local_position_ned_encode(boot_ms, *map(float, p), *map(float, v)))
        for name, send in self._extra_senders.items():
            if now >= due[name]:
                due[name] = now + 1.0 / self.rates_hz[name]
                send(boot_ms)
        if now >= self._next_target_s:
            self._next_target_s = now + 1.0 / TARGET_POSITION_HZ
            tp, tv = enu_to_ned(self.target.p), enu_to_ned(self.target.v)
            self._as_target(
                lambda: link.send(
                    mav.local_position_ned_encode(boot_ms, *map(float, tp), *map(float, tv))
                )
            )
        while self._frames and self._frames[0][0] <= now:
            _send_t, _, cap_t, frame = heapq.heappop(self._frames)
            self.camera.publish(frame, cap_t, now - cap_t)

    def _senders(self) -> dict:
        return {
            "GLOBAL_POSITION_INT": self._send_global,
            "EXTENDED_SYS_STATE": lambda _ms: self.link.send(
                self.link.mav.extended_sys_state_encode(
                    mavlink.MAV_VTOL_STATE_UNDEFINED, self.landed_state
                )
            ),
            "SYS_STATUS": self._send_sys_status,
            "BATTERY_STATUS": self._send_battery,
            "HOME_POSITION": self._send_home,
        }

    def _send_global(self, boot_ms: int) -> None:
        veh = self.vehicle
        lat, lon, alt = self.opt.home.to_global(veh.p)
        v = enu_to_ned(veh.v)
        hdg = (90.0 - math.degrees(self._yaw())) % 360.0
        self.link.send(
            self.link.mav.global_position_int_encode(
                boot_ms,
                round(lat * 1e7),
                round(lon * 1e7),
                round(alt * 1000.0),
                round(veh.p[2] * 1000.0),
                *(max(-32767, min(32767, round(100.0 * c))) for c in v),
                round(100.0 * hdg) % 36000,
            )
        )

    def _send_home(self, _boot_ms: int) -> None:
        h = self.opt.home
        self.link.send(
            self.link.mav.home_position_encode(
                round(h.lat_deg * 1e7),
                round(h.lon_deg * 1e7),
                round(h.alt_m * 1000.0),
                0.0,
                0.0,
                0.0,
                [1.0, 0.0, 0.0, 0.0],
                0.0,
                0.0,
                0.0,
                int(self.time_s * 1e6),
            )
        )

    def _send_sys_status(self, _boot_ms: int) -> None:
        b = self.battery
        self.link.send(
            self.link.mav.sys_status_encode(
                SENSORS_HEALTHY,
                SENSORS_HEALTHY,
                SENSORS_HEALTHY,
                250,
                round(b.voltage_v * 1000.0),
                round(b.current_a * 100.0),
                round(100.0 * b.remaining),
                0,
                0,
                0,
                0,
                0,
                0,
            )
        )

    def _send_battery(self, _boot_ms: int) -> None:
        b = self.battery
        self.link.send(
            self.link.mav.battery_status_encode(
                0,
                mavlink.MAV_BATTERY_FUNCTION_ALL,
                mavlink.MAV_BATTERY_TYPE_LIPO,
                2500,
                b.cell_voltages_mv,
                round(b.current_a * 100.0),
                round(b.consumed_mah),
                -1,
                round(100.0 * b.remaining),
                0,
                mavlink.MAV_BATTERY_CHARGE_STATE_OK,
            )
        )

    def _send_version(self) -> None:
        caps = (
            mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2
            | mavlink.MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET
            | mavlink.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
            | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
        )
        self.link.send(
            self.link.mav.autopilot_version_encode(
                caps, 0x010F0000, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0, 1
            )
        )

    def _as_target(self, send) -> None:
        mav = self.link.mav
        mav.srcSystem = TARGET_SYSTEM_ID
        try:
            send()
        finally:
            mav.srcSystem = VEHICLE_SYSTEM_ID

    # ------------------------------------------------------------------ run
    def stop(self) -> None:
        self._stop.set()

    def run(self, duration_s: float | None = None) -> dict | None:
        t0 = self._t0 = time.perf_counter()
        print(f"sitl: boot clock zero at monotonic {t0:.6f} s", file=self.out, flush=True)
        self._say(
            mavlink.MAV_SEVERITY_INFO,
            f"SITL up: {self.scenario.name}, {px4_mode_name(self.custom_mode)}",
        )
        print(f"sitl: camera {self.camera.url}, MAVLink {self.link.url}", file=self.out, flush=True)
        while not self._stop.is_set():
            now = time.perf_counter() - t0
            if duration_s is not None and now >= duration_s:
                break
            n = 0
            while self.time_s + self.dt_s <= now and n < PHYSICS_HZ // 10:
                self.step()
                n += 1
            if n == PHYSICS_HZ // 10:  # far behind (a stall): drop the backlog, stay real time
                self.step_index = int(now / self.dt_s)
            self._handle(self.time_s)
            self._send_due(self.time_s)
            if not self.vehicle.finite():
                self._say(mavlink.MAV_SEVERITY_CRITICAL, "vehicle state not finite: stopping")
                break
            wait = max(0.0, (self.step_index + 1) * self.dt_s - (time.perf_counter() - t0))
            try:  # woken by an arriving frame, as PX4's receiver thread is (prompt TIMESYNC)
                select.select([self.link.conn.port], [], [], wait)
            except (OSError, ValueError, TypeError, AttributeError):
                time.sleep(wait)
        return self.result
