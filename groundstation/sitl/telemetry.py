"""MAVLink out, for :class:`.vehicle.SitlVehicle` (a mixin over its state): the
``HEARTBEAT``, the state streams at their rates (``MAV_CMD_SET_MESSAGE_INTERVAL`` changes
them), the target as system 2, and the camera frames once their delay has passed."""

from __future__ import annotations

import heapq
import math

import numpy as np

from onboard.geometry import quat_to_rotmat
from onboard.link.px4 import (
    TARGET_SYSTEM_ID,
    VEHICLE_SYSTEM_ID,
    enu_to_ned,
    flu_to_frd,
    mavlink,
    quat_enu_flu_to_ned_frd,
)

from .autopilot import SENSORS_HEALTHY

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
TARGET_POSITION_HZ = 20.0


class SitlTelemetry:
    """The MAVLink-out half of :class:`.vehicle.SitlVehicle`."""

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
            est = self.estimated_state()
            q = quat_enu_flu_to_ned_frd(est.attitude_wxyz)
            w = flu_to_frd(est.body_rates_flu_rad_s)
            link.send(
                mav.attitude_quaternion_encode(
                    boot_ms, *(float(c) for c in q), float(w[0]), float(w[1]), float(w[2])
                )
            )
        if now >= due["HIGHRES_IMU"]:
            due["HIGHRES_IMU"] = now + 1.0 / self.rates_hz["HIGHRES_IMU"]
            noise = self._gyro_rng.standard_normal(3) * self.scenario.sim.gyro_noise_rad_s
            rates = np.array(veh.read_gyro()) + noise
            if self.estimate is not None:  # plus the gyro bias
                rates = self.estimate.gyro(self.time_s, rates)
            g = flu_to_frd(rates)
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
            est = self.estimated_state()
            p, v = enu_to_ned(est.position_enu_m), enu_to_ned(est.velocity_enu_m_s)
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
            # the capture stamp carries the camera-IMU offset: the age is never negative
            self.camera.publish(frame, cap_t, max(now - cap_t, 0.0))

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
        est = self.estimated_state()
        lat, lon, alt = self.opt.home.to_global(est.position_enu_m)
        v = enu_to_ned(est.velocity_enu_m_s)
        hdg = (90.0 - math.degrees(self._yaw())) % 360.0
        self.link.send(
            self.link.mav.global_position_int_encode(
                boot_ms,
                round(lat * 1e7),
                round(lon * 1e7),
                round(alt * 1000.0),
                round(est.position_enu_m[2] * 1000.0),
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
