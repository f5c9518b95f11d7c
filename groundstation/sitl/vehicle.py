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

What the onboard computer is told carries the errors of a real PX4, from the simulator's own
models (one implementation each, the same scenario keys and ``--set`` switches): the
state-estimate model of :mod:`..sim.estimate` (``[estimate]``: position, velocity and attitude
errors and lag, gyro bias in ``HIGHRES_IMU`` and the reported rates, the camera-IMU stamp
offset in each frame's capture time, the thrust scale and command latency applied to the
offboard setpoints) and the detector faults of :mod:`..sim.camera` (``[camera]``: bursty frame
drops, false red blobs drawn into the frame, a balloon narrower than ``min_blob_px`` left out).
The model's lags are what a loop tick sees; the SITL's streams already make each sample up to
one period old by the time the runtime ticks, so half a period (their mean age) is taken off
the modelled lag (:func:`sitl_estimate_spec`). PX4's own hold and AUTO modes fly on the truth.

The target starts moving, and the sortie clock starts, when the vehicle first enters
offboard; the closest approach is then tracked in continuous time, and the result printed as
one ``SITL_RESULT {json}`` line when the vehicle passes the target.

This module keeps the vehicle's state, PX4's hold and AUTO modes, the physics and the
camera; what arrives over MAVLink is handled in :mod:`.commands`, what is sent in
:mod:`.telemetry` (both mixed into :class:`SitlVehicle`).
"""

from __future__ import annotations

import heapq
import json
import math
import select
import sys
import threading
import time
from collections import deque
from dataclasses import dataclass, field, replace

import numpy as np

from onboard.camera_model import CameraModel
from onboard.control.attitude import attitude_command
from onboard.datatypes import VehicleState
from onboard.enums import Outcome
from onboard.gains import Gains
from onboard.geometry import as_quat, camera_attitude, quat_to_rotmat, wrap_pi
from onboard.link.px4 import MODE_HOLD, MODE_OFFBOARD, MavLink, mavlink, px4_mode_name

from ..scenario import EstimateSpec, Scenario
from ..sim.camera import DetectorFaults, sphere_in_view
from ..sim.estimate import StateEstimateModel
from ..sim.outcome import closest_in_step
from ..sim.physics import PASS_RADIUS_M
from ..sim.render import FrameRenderer
from ..sim.targets import Target
from ..sim.vehicle import Multicopter
from ..sim.wind import Wind
from .autopilot import MODE_LAND, MODE_RTL, MODE_TAKEOFF, AutopilotParams, Battery, Home
from .camera_server import CameraServer
from .commands import SitlCommands
from .telemetry import RATES_HZ, SitlTelemetry

PHYSICS_HZ = 600
RTL_CRUISE_M_S = 5.0  # PX4's MPC_XY_CRUISE


@dataclass
class SitlOptions:
    offboard_loss_s: float = 1.0  # PX4 COM_OF_LOSS_T (a parameter: PARAM_SET changes it)
    camera_blackout_after_s: float | None = None  # fault injection: no frames after this
    seed: int = 0
    home: Home = field(
        default_factory=Home
    )  # where local (0, 0, 0) is: GLOBAL_POSITION_INT, HOME_POSITION
    on_ground: bool = False  # start disarmed and landed below the scenario's start position


def sitl_estimate_spec(spec: EstimateSpec, rates_hz: dict[str, float]) -> EstimateSpec:
    """The estimate model's lags less the mean age (half a period) the SITL's own
    ``LOCAL_POSITION_NED`` and ``ATTITUDE_QUATERNION`` streams add at the runtime's tick,
    so that the loop sees the modelled lag on average, as in the simulator."""
    return replace(
        spec,
        lag_s=max(spec.lag_s - 0.5 / rates_hz["LOCAL_POSITION_NED"], 0.0),
        att_lag_s=max(spec.att_lag_s - 0.5 / rates_hz["ATTITUDE_QUATERNION"], 0.0),
    )


class SitlVehicle(SitlCommands, SitlTelemetry):
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
        # the estimate model's streams are the next child, as in the simulator
        est_seed = ss.spawn(1)[0]
        self.estimate = (
            StateEstimateModel(sitl_estimate_spec(scenario.estimate, RATES_HZ), est_seed)
            if scenario.estimate.enabled
            else None
        )
        self._est_now: VehicleState | None = None  # the estimate at its time (one a step)
        # the detector faults' own stream, spawned from the camera's as the simulator does
        self.faults = DetectorFaults(scenario.camera, cam_rng.spawn(1)[0])
        self._commands: deque = deque()  # (due time, body rates, thrust) to the actuators
        self._actuator: tuple[np.ndarray, float] | None = None  # what the actuators fly
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
            self.vehicle.p = [*self.vehicle.p[:2], 0.0]
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
        self._ended_closing = False  # the last step ended with the range still falling
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

    def estimated_state(self) -> VehicleState:
        """What PX4's estimator says now: the truth through the estimate model (the truth
        itself with ``estimate.enabled = false``); computed once per physics step."""
        t = self.time_s
        est = self._est_now
        if est is not None and est.time_s == t:
            return est
        truth = self.vehicle.state(t)
        self._est_now = truth if self.estimate is None else self.estimate.vehicle_state(truth)
        return self._est_now

    def _queue_setpoint(self, now: float) -> None:
        """An accepted setpoint reaches the actuators after the command latency, with the
        thrust off by the sortie's thrust scale (the estimate model's actuation errors)."""
        rates, thrust = self.setpoint
        est = self.estimate
        if est is None:
            self._commands.append((now, rates, thrust))
        else:
            self._commands.append((now + est.command_delay_s, rates, thrust * est.thrust_scale))

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
        veh.v, veh.w, veh.p = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [*veh.p[:2], 0.0]
        veh.thrust_n = veh.cmd_thrust_n = 0.0
        delay = self.params["COM_DISARM_LAND"]
        if self.armed and self._landed_at_s is not None and 0 <= delay <= t - self._landed_at_s:
            self.armed = False
            self._landed_at_s = None
            self._say(mavlink.MAV_SEVERITY_INFO, "Disarmed by landing")
        return True

    def _touchdown(self, t: float) -> None:
        veh = self.vehicle
        veh.p, veh.v = [*veh.p[:2], 0.0], [0.0, 0.0, 0.0]
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
        cmds = self._commands
        while cmds and cmds[0][0] <= t + 1e-9:  # setpoints reach the actuators
            self._actuator = cmds.popleft()[1:]
        if self.custom_mode == MODE_OFFBOARD:
            if t - self.last_setpoint_s > self.params["COM_OF_LOSS_T"]:
                self._enter_hold("offboard loss: no setpoints")
            elif self._actuator is not None:
                veh.command(*self._actuator)
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
            self.target.advance(ts + self.dt_s, self.dt_s, wind.at(self.target.p), veh.p)
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
        dist, s, _, closing, opening, ended_closing = closest_in_step(r0, r1)
        if dist < self.miss_m:
            self.miss_m = dist
            self.closest = (ts + s * self.dt_s, speed)
        # over: opening now, closing at the step's start or at the end of the one before
        closing, self._ended_closing = closing or self._ended_closing, ended_closing
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
        burst_drop, clutter = self.faults.frame()
        # the capture stamp's error (camera-IMU offset): one draw a frame, as in the simulator
        stamp_err = 0.0 if self.estimate is None else self.estimate.stamp_error_s()
        if dropped or burst_drop or self.camera.clients == 0:
            return
        m, diameter = self.camera_model, self.scenario.target.diameter_m
        R_WC = camera_attitude(as_quat(self.vehicle.q), np.array(m.R_BC))
        cam_p, tgt_p = np.array(self.vehicle.p), np.array(self.target.p)
        visible = spec.min_blob_px <= 0.0 or self.faults.big_enough(
            2.0 * sphere_in_view(m, R_WC, cam_p, tgt_p, diameter)[1]
        )
        false_blob = None
        if clutter is not None:
            self.faults.false_detections += 1
            false_blob = (clutter[0] * m.width_px, clutter[1] * m.height_px, spec.false_blob_px)
        frame = self.renderer.render(
            R_WC, cam_p, tgt_p, diameter, clutter_px=false_blob, target_visible=visible
        )
        self._n += 1
        heapq.heappush(self._frames, (t + delay, self._n, t + stamp_err, frame))

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
