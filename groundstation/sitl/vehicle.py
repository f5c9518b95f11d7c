"""``groundstation sitl``: the simulator as a PX4-like quadrotor on a MAVLink link.

It advances the same vehicle, target and wind models as the simulator in real time and
behaves as PX4 does towards an offboard computer:

- ``HEARTBEAT`` as a PX4 quadrotor (custom mode: main mode << 16 | sub mode << 24), armed
  and airborne in HOLD (AUTO_LOITER) at the scenario's start position;
- ``ATTITUDE_QUATERNION`` and ``HIGHRES_IMU`` at 200 Hz, ``LOCAL_POSITION_NED`` at 100 Hz
  (NED/FRD, converted by :mod:`onboard.link.px4`);
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
import sys
import threading
import time
from dataclasses import dataclass

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
    TARGET_SYSTEM_ID,
    VEHICLE_SYSTEM_ID,
    MavLink,
    all_finite,
    enu_to_ned,
    flu_to_frd,
    frd_to_flu,
    mavlink,
    px4_mode_name,
    quat_enu_flu_to_ned_frd,
)

from ..scenario import Scenario
from ..sim.render import FrameRenderer
from ..sim.simulation import PASS_RADIUS_M, closest_in_step
from ..sim.targets import Target
from ..sim.vehicle import Multicopter
from ..sim.wind import Wind
from .camera_server import CameraServer

PHYSICS_HZ = 600
RATES_HZ = {"ATTITUDE_QUATERNION": 200.0, "HIGHRES_IMU": 200.0, "LOCAL_POSITION_NED": 100.0}
TARGET_POSITION_HZ = 20.0
OFFBOARD_STREAM_S = 0.5  # a setpoint this recent is needed to enter offboard
MAX_RATE_CMD_RAD_S = 20.0


@dataclass
class SitlOptions:
    offboard_loss_s: float = 1.0  # PX4 COM_OF_LOSS_T
    camera_blackout_after_s: float | None = None  # fault injection: no frames after this
    seed: int = 0


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
        self.target = Target(scenario.target)
        self.wind = Wind(scenario.wind, wind_rng)
        self.target.settle_in_wind(scenario.wind.mean_m_s)
        self.dt_s = 1.0 / PHYSICS_HZ
        self.step_index = 0
        self.armed = True
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
        self.hold_p = list(self.vehicle.p)
        self.hold_yaw = self._yaw()
        self._say(
            mavlink.MAV_SEVERITY_WARNING if why else mavlink.MAV_SEVERITY_INFO,
            f"HOLD{': ' + why if why else ''}",
        )

    # ------------------------------------------------------------------ PX4's hold
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

    # ------------------------------------------------------------------ physics
    def step(self) -> None:
        k = self.step_index
        t = k * self.dt_s
        veh = self.vehicle
        if k % self._cam_div == 0:
            self._capture(t)
        if self.custom_mode == MODE_OFFBOARD:
            if t - self.last_setpoint_s > self.opt.offboard_loss_s:
                self._enter_hold("offboard loss: no setpoints")
            elif self.setpoint is not None:
                veh.command(*self.setpoint)
        if self.custom_mode != MODE_OFFBOARD and k % self._hold_div == 0:
            self._hold_command()
        wind = self.wind.velocity_m_s
        veh.step(self.dt_s, wind)
        if self.sortie_start_s is not None:
            ts = t - self.sortie_start_s
            self.target.advance(ts + self.dt_s, self.dt_s, wind)
            self._track_closest(ts)
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
                elif (
                    kind == "COMMAND_LONG"
                    and msg.target_system in (VEHICLE_SYSTEM_ID, 0)
                    and msg.target_component in (AUTOPILOT_COMPONENT_ID, 0)
                ):
                    self._command(msg, now)
            except (ValueError, TypeError, OverflowError, KeyError):
                self.link.bad_frames += 1  # a valid frame carrying nonsense (a NaN mode...)

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

    def _command(self, msg, now: float) -> None:
        cmd = msg.command
        if cmd == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            if msg.param1 == 1.0:
                self.armed = True
                self._ack(msg, mavlink.MAV_RESULT_ACCEPTED)
            else:
                self._ack(msg, mavlink.MAV_RESULT_DENIED)  # airborne: no disarm
                self._say(mavlink.MAV_SEVERITY_WARNING, "disarm refused: in air")
        elif cmd == mavlink.MAV_CMD_DO_SET_MODE:
            main, _sub = int(msg.param2), int(msg.param3)
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
            elif main in (PX4_MAIN_AUTO, PX4_MAIN_POSCTL):
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
                mavlink.MAV_STATE_ACTIVE,
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
        t0 = time.perf_counter()
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
            time.sleep(max(0.0, (self.step_index + 1) * self.dt_s - (time.perf_counter() - t0)))
        return self.result
