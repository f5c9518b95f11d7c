"""The closed interception loop: DKF -> guidance -> FOV hold -> attitude loop, one tick at a
time (DESIGN.md §3). The simulator drives this object and so does the MAVLink runtime; it owns
no clock, socket or camera, only the time stamps it is handed.
"""

from __future__ import annotations

import math

import numpy as np

from .camera_model import CameraModel
from .control.attitude import attitude_command
from .control.disturbance import (
    DisturbanceObserver,
    DisturbanceObserverConfig,
    feedforward_accel,
)
from .control.fov_hold import yaw_rate_command
from .control.guidance import (
    GUIDANCE_LAWS,
    GuidanceInput,
    direction_angles,
    line_of_sight,
    los_change,
    normal_component,
    saturate_norm,
    smooth_los_change,
)
from .datatypes import (
    ControlTelemetry,
    Detection,
    GyroSample,
    LoopMode,
    RateThrustCommand,
    VehicleParams,
    VehicleState,
)
from .estimation.dkf import DelayedKalmanFilter, DkfConfig, FusionResult
from .gains import Gains
from .geometry import quat_to_rotmat

_NAN2 = (math.nan, math.nan)


class InterceptionLoop:
    """Call :meth:`on_gyro` and :meth:`on_detection` as samples arrive, and :meth:`tick` at
    the control rate; each tick returns the command and what was computed for it."""

    def __init__(
        self,
        camera: CameraModel,
        vehicle: VehicleParams,
        gains: Gains | None = None,
        law: str = "png",
        control_rate_hz: float = 100.0,
        dkf_config: DkfConfig | None = None,
    ) -> None:
        if law not in GUIDANCE_LAWS:
            raise ValueError(f"unknown guidance law {law!r}; choose one of {sorted(GUIDANCE_LAWS)}")
        if not control_rate_hz > 0.0:
            raise ValueError("control_rate_hz must be positive")
        self.camera = camera
        self.vehicle = vehicle
        self.law_name = law
        self._law = GUIDANCE_LAWS[law]
        self.gains = gains or Gains()
        self._pending_gains: Gains | None = None
        self.nominal_dt_s = 1.0 / control_rate_hz
        self.dkf = DelayedKalmanFilter(camera, dkf_config)
        self._gyro_sum = np.zeros(3)
        self._gyro_n = 0
        self._detections: list[Detection] = []
        self._prev_time_s: float | None = None
        self._prev_R_WC: np.ndarray | None = None
        self.last_fusion: list[FusionResult] = []
        self._fused_early: list[FusionResult] = []  # by fuse_detections() since the last tick
        self.guard_trips = 0
        self.acquired = False
        self.disturbance = DisturbanceObserver(
            DisturbanceObserverConfig(
                self.gains.k_dob,
                vehicle.mass_kg,
                vehicle.max_thrust_n,
                max_m_s2=self.gains.a_max,
                drag_per_mass_1_s=self.gains.k_drag,
            )
        )
        self._dq_filt = _NAN2  # low-passed LOS change (gains.tau_los)
        # the image's top/bottom edges above body x (upright: a portrait camera's long side)
        roll = math.radians(camera.mount_roll_deg)
        half_v = math.atan(
            (abs(math.cos(roll)) * camera.height_px + abs(math.sin(roll)) * camera.width_px)
            / (2.0 * camera.f_px)
        )
        pitch = math.radians(camera.mount_pitch_deg)
        self.fov_edges_rad = (pitch + half_v, pitch - half_v)

    @property
    def last_tick_time_s(self) -> float | None:
        """Time of the last tick, or None before the first."""
        return self._prev_time_s

    # ------------------------------------------------------------------ inputs
    def set_gains(self, gains: Gains) -> None:
        """Use ``gains`` from the next tick on (they are validated on construction)."""
        self._pending_gains = gains

    def on_gyro(self, sample: GyroSample) -> None:
        self._gyro_sum += sample.rates_flu_rad_s
        self._gyro_n += 1

    def on_detection(self, detection: Detection) -> None:
        self._detections.append(detection)

    def fuse_detections(self) -> list[FusionResult]:
        """Fuse the detections handed in so far into the DKF now, against its last prediction,
        instead of in the next tick (the runtime calls this on the camera thread as a detection
        arrives, so the tick only predicts). Their results appear in the next tick's
        ``last_fusion``. Call it from one thread at a time with :meth:`tick`."""
        out = [
            self.dkf.fuse(det) for det in sorted(self._detections, key=lambda d: d.capture_time_s)
        ]
        self._detections.clear()
        self._fused_early.extend(out)
        return out

    # ------------------------------------------------------------------ the tick
    def tick(self, state: VehicleState, brake: bool = False) -> ControlTelemetry:
        """One control tick at ``state.time_s``; with ``brake`` the estimate keeps running but
        the command brakes and holds (an operator abort)."""
        t = state.time_s
        if self._pending_gains is not None:
            self.gains, self._pending_gains = self._pending_gains, None
            g = self.gains
            self.disturbance.set_bandwidth(g.k_dob, g.a_max, g.k_drag)
        gains = self.gains
        dt = self.nominal_dt_s if self._prev_time_s is None else t - self._prev_time_s
        if not dt > 0.0:
            dt = self.nominal_dt_s

        gyro = self._gyro_sum / self._gyro_n if self._gyro_n else state.body_rates_flu_rad_s
        self._gyro_sum = np.zeros(3)
        self._gyro_n = 0
        R_WB = quat_to_rotmat(state.attitude_wxyz)
        R_WC = R_WB @ self.camera.R_BC
        v = state.velocity_enu_m_s
        self.dkf.predict(t, gyro, v, R_WC)
        self.last_fusion, self._fused_early = self._fused_early, []
        if self._detections:
            for det in sorted(self._detections, key=lambda d: d.capture_time_s):
                self.last_fusion.append(self.dkf.fuse(det))
            self._detections.clear()

        d_hat = self.disturbance.update(t, v, R_WB[:, 2])
        est = self.dkf.estimate()
        e_est = e_rate = None
        q_y = q_z = s_y = s_z = math.nan
        yaw_rate = 0.0
        if brake or est is None or est.lost:
            mode = LoopMode.BRAKE if brake else LoopMode.LOST if self.acquired else LoopMode.WAITING
            self._dq_filt = _NAN2
            a_d = saturate_norm(-gains.k_brake * v, gains.a_max)  # brake and hold
            if est is not None and not est.lost:
                e_est, e_rate = est.e_px, est.e_rate_px_s
        else:
            mode = LoopMode.TRACKING
            self.acquired = True
            e_est, e_rate = est.e_px, est.e_rate_px_s
            f = self.camera.f_px
            n_t = line_of_sight(e_est[0] / f, e_est[1] / f, R_WC)
            q_y, q_z = direction_angles(n_t)
            dq_y = dq_z = 0.0
            prev = None if self._prev_time_s is None else self.dkf.e_px_at(self._prev_time_s)
            if prev is not None and self._prev_R_WC is not None:
                # previous LOS from the replay-corrected buffered estimate: a fused detection
                # moves both ends of the difference, so Delta q carries no correction jump
                n_prev = line_of_sight(prev[0] / f, prev[1] / f, self._prev_R_WC)
                dq_y, dq_z = los_change(q_y, q_z, *direction_angles(n_prev))
            if gains.tau_los > 0.0:
                dq_y = smooth_los_change(self._dq_filt[0], dq_y, dt, gains.tau_los)
                dq_z = smooth_los_change(self._dq_filt[1], dq_z, dt, gains.tau_los)
                self._dq_filt = (dq_y, dq_z)
            e_n = (e_est[0] / f, e_est[1] / f)
            out = self._law(
                GuidanceInput(dt, n_t, q_y, q_z, dq_y, dq_z, v, e_n, R_WC, self.fov_edges_rad),
                gains,
            )
            a_d, s_y, s_z = out.accel_desired_enu_m_s2, out.vel_elev_rad, out.vel_azim_rad
            e_lat_px = self.camera.upright(*e_est)[0]
            e_lat_rate_px_s = self.camera.upright(*e_rate)[0]
            yaw_rate = yaw_rate_command(e_lat_px, e_lat_rate_px_s, gains)

        # disturbance feed-forward: the attitude loop flies a_d - d^ (normal to v in flight;
        # the guidance limit a_max applies to a_d, |d^| is clamped to a_max by the observer)
        a_cmd = a_d + feedforward_accel(d_hat, v, gains.v_min) if self.disturbance.enabled else a_d
        omega, thrust = attitude_command(a_cmd, R_WB, yaw_rate, gains, self.vehicle)
        w0, w1, w2 = omega.tolist()
        finite = math.isfinite(w0) and math.isfinite(w1) and math.isfinite(w2)
        guard = not (finite and math.isfinite(thrust) and 0.0 <= thrust <= 1.0)
        if guard:
            # never hand a non-finite or out-of-range command on: level hover instead
            self.guard_trips += 1
            omega = np.zeros(3)
            thrust = self.vehicle.hover_thrust_normalised
        self.disturbance.commanded(float(thrust))
        self._prev_time_s = t
        self._prev_R_WC = R_WC
        return ControlTelemetry(
            time_s=t,
            mode=mode,
            law=self.law_name,
            e_est_px=e_est,
            e_rate_est_px_s=e_rate,
            los_elev_rad=q_y,
            los_azim_rad=q_z,
            vel_elev_rad=s_y,
            vel_azim_rad=s_z,
            accel_desired_enu_m_s2=a_d,
            accel_normal_desired_m_s2=normal_component(a_d, v),
            yaw_rate_cmd_rad_s=yaw_rate,
            command=RateThrustCommand(t, omega, float(thrust)),
            dkf_time_since_detection_s=(math.inf if est is None else est.time_since_detection_s),
            dkf_lost=est is None or est.lost,
            guard_tripped=guard,
        )
