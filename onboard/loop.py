"""The closed interception loop: DKF -> guidance -> FOV hold -> attitude loop, one tick at a
time (DESIGN.md §3). The simulator drives this object and so does the MAVLink runtime; it owns
no clock, socket or camera, only the time stamps it is handed."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .camera_model import CameraModel
from .control.apn import available_lateral_accel_m_s2, manoeuvre_accel_m_s2, time_to_go_s
from .control.attitude import command_floats
from .control.clearance import (
    brake_accel,
    clearance_guard_accel,
    range_interval_m,
    track_speed_cap_m_s,
    upward_accel_m_s2,
)
from .control.disturbance import DisturbanceObserver, DisturbanceObserverConfig
from .control.fov_hold import yaw_rate_command
from .control.guidance import (
    GUIDANCE_LAWS,
    GuidanceInput,
    believed_drag_floats,
    direction_angles,
    line_of_sight,
    los_terms,
    png_command,
    png_law,
)
from .control.reacquire import floor_guard_accel, reacquire_accel, search_accel, search_yaw_rate
from .datatypes import (
    GRAVITY_M_S2,
    ControlTelemetry,
    Detection,
    GyroSample,
    LoopMode,
    RateThrustCommand,
    VehicleParams,
    VehicleState,
)
from .enums import DEFAULT_LAW, GuidanceLaw
from .estimation.dkf import DelayedKalmanFilter, DkfConfig, FusionResult, ImageEstimate
from .estimation.dkf_values import measurement
from .estimation.imm import MotionEstimate, TargetMotionImm
from .estimation.own_velocity import OwnVelocityFilter
from .estimation.self_calibration import SelfCalEstimate, SelfCalibration
from .gains import Gains
from .geometry import (
    as_quat,
    body_and_camera_attitude,
    mat3_mul,
    propagate_rotation,
    rotmat_of_quat,
)
from .gyro_turn import GyroTurn
from .track_loss import TrackLossLadder

_NAN2 = (math.nan, math.nan)
_NO_FLOWN = (math.nan, math.nan, math.nan)  # (dq_y, dq_z, hold): no command's LOS change yet
MAX_LATE_CARRY = 1.0  # a late tick takes back at most this many of the last command's turns


class InterceptionLoop:
    """Call :meth:`on_gyro` and :meth:`on_detection` as samples arrive, and :meth:`tick` at
    the control rate; each tick returns the command and what was computed for it."""

    def __init__(
        self,
        camera: CameraModel,
        vehicle: VehicleParams,
        gains: Gains | None = None,
        law: str = DEFAULT_LAW.value,
        control_rate_hz: float = 100.0,
        dkf_config: DkfConfig | None = None,
        estimate_motion: bool = False,
    ) -> None:
        """``estimate_motion``: run the IMM of the target's motion (onboard/estimation/imm.py)
        for the telemetry even when the law does not use it (the augmented law always runs
        it)."""
        if law not in GUIDANCE_LAWS:
            raise ValueError(f"unknown guidance law {law!r}; choose one of {sorted(GUIDANCE_LAWS)}")
        if not control_rate_hz > 0.0:
            raise ValueError("control_rate_hz must be positive")
        self.camera = camera
        self._R_BC = np.array(camera.R_BC)  # writable, as the kernels take it
        self._offset_b_m = camera.offset_b_m
        self.vehicle = vehicle
        self.law_name = law
        self._law = GUIDANCE_LAWS[law]
        self.gains = gains or Gains()
        self._pending_gains: Gains | None = None
        self.nominal_dt_s = 1.0 / control_rate_hz
        self.dkf = DelayedKalmanFilter(camera, dkf_config)
        self.dkf.carry_max_s = self.gains.t_carry
        uses_motion = estimate_motion or law == GuidanceLaw.APN.value
        self.motion = TargetMotionImm() if uses_motion else None
        self._fused_capture_s: list[float] = []  # capture times fused since the last tick
        self._motion_now: MotionEstimate | None = None  # the IMM's, predicted to the tick
        self._dkf_belief = self.dkf.config  # the operator's settings (self-calibration's prior)
        self.self_cal = SelfCalibration(camera.f_px, camera.R_BC, self.dkf.config.target_diameter_m)
        self._self_cal_est: SelfCalEstimate = self.self_cal.estimate()
        self._los_prev: np.ndarray | None = None  # the last tick's estimated LOS (ENU, unit)
        self.gyro_turn = GyroTurn(self.nominal_dt_s)  # the body's turn between ticks
        self._detections: list[Detection] = []
        self._prev_time_s: float | None = None
        self._prev_R_WC: np.ndarray | None = None
        self.last_fusion: list[FusionResult] = []
        self._fused_early: list[FusionResult] = []  # by fuse_detections() since the last tick
        self.guard_trips = 0
        self.speed_cap_m_s = math.inf  # the last tick's approach speed limit (clearance.py)
        self._target_low_m = -math.inf  # the target's lowest height held over the track
        self.ladder = TrackLossLadder(camera, self.dkf)  # track loss, re-acquisition, search
        self.mode = LoopMode.WAITING
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
        self._dq_flown = _NO_FLOWN  # the last command's (dq_y, dq_z, hold_s) (los_terms)
        self._thrust_n = vehicle.mass_kg * GRAVITY_M_S2  # last commanded thrust (N)
        self.own_velocity = OwnVelocityFilter(self.gains.tau_vel)  # gains.tau_vel
        self.fov_edges_rad = camera.fov_edges_rad  # the image's top and bottom above body x

    @property
    def last_tick_time_s(self) -> float | None:
        """Time of the last tick, or None before the first."""
        return self._prev_time_s

    # ------------------------------------------------------------------ inputs
    def set_gains(self, gains: Gains) -> None:
        """Use ``gains`` from the next tick on (they are validated on construction)."""
        self._pending_gains = gains

    def set_dkf_config(self, config: DkfConfig) -> None:
        """Use the filter settings ``config`` (target diameter, noises, gate) from the next
        prediction or fusion on; the track is kept. Its target diameter is the operator's
        belief that the in-flight size estimate starts from."""
        self._dkf_belief = config
        self.self_cal.set_believed_diameter(config.target_diameter_m)
        self._self_cal_est = self.self_cal.estimate()
        self.dkf.config = config
        self._use_size(self.gains)

    def on_gyro(self, sample: GyroSample) -> None:
        self.gyro_turn.add(sample.rates_flu_rad_s)

    def on_detection(self, detection: Detection) -> None:
        """Queue a detection (the lens's pixels) for the next tick, undistorted with the
        camera calibration the loop believes (:meth:`.CameraModel.undistorted`)."""
        self._detections.append(self.camera.undistorted(detection))

    def _track_motion(
        self,
        t: float,
        est: ImageEstimate | None,
        state: VehicleState,
        R_WB: np.ndarray,
        gyro: np.ndarray,
    ) -> MotionEstimate | None:
        """Feed the IMM, for each detection fused since the last tick, the target's position
        in the DKF's buffered state at its capture time (the measurement's information, none
        of the camera delay's prediction), placed from the pose the own velocity the DKF's
        relative motion uses and the gyro carried then (imm.CarriedPose) and stamped with that
        time; the estimate is then predicted to ``t``. A lost estimate ends the IMM's track."""
        motion, times = self.motion, self._fused_capture_s
        self._fused_capture_s = []
        if est is None:
            motion.reset()
            self._motion_now = None
            return None
        motion.pose.step(t, state.position_enu_m, self.own_velocity.velocity_enu_m_s, R_WB, gyro)
        if est.lost:  # a dropout: the IMM keeps its track (it restarts after its own max gap)
            return None
        rows = [self.dkf.state_at_capture(t_c) for t_c in sorted(times)]
        fed = [motion.update_buffered(*r, self._R_BC, self._offset_b_m) for r in rows if r]
        if any(fed):
            self._motion_now = motion.predicted(t)
        return self._motion_now

    def fuse_detections(self) -> list[FusionResult]:
        """Fuse the detections handed in so far into the DKF now, against its last prediction,
        instead of in the next tick (the runtime calls this on the camera thread as a detection
        arrives, so the tick only predicts). While the track is stale they pass the screen
        first, against the last tick's camera attitude. Their results appear in the next tick's
        ``last_fusion``. Call it from one thread at a time with :meth:`tick`."""
        dets = sorted(self._detections, key=lambda d: d.capture_time_s)
        self._detections.clear()
        ladder = self.ladder
        if dets and ladder.attitudes and ladder.screening(self._prev_time_s):
            dets = ladder.screened(dets, ladder.attitudes[-1][1], self.gains)
        out = [self._fuse(det) for det in dets]
        self._fused_early.extend(out)
        return out

    def _fuse(self, det: Detection) -> FusionResult:
        """Fuse one detection, its stamp moved to the gyro's timeline by the in-flight
        camera-offset estimate (gain k_selfcal), and feed the in-flight estimates with it."""
        cal = self.self_cal
        use = self.gains.k_selfcal >= 0.5
        t_c = det.capture_time_s
        if use and isinstance(t_c, int | float) and math.isfinite(t_c):
            t_new = cal.restamp(t_c)
            if t_new != t_c:
                det = Detection(t_new, det.center_px, det.bbox_px, det.area_px, det.score)
        result = self.dkf.fuse(det)
        fused = result is FusionResult.ACCEPTED or result is FusionResult.INITIALISED
        if fused and self.motion is not None:
            self._fused_capture_s.append(det.capture_time_s)  # the IMM's (_track_motion)
        if result is FusionResult.ACCEPTED:
            m = measurement(det, self.camera)
            if m is not None:
                cal.on_fused(float(t_c), (float(m.z[0]), float(m.z[1])), m.r_px)
                self._self_cal_est = cal.estimate()
                if use:
                    self._use_size(self.gains)
        return result

    def _use_size(self, gains: Gains) -> None:
        """Give the DKF the in-flight target diameter (gain k_selfcal; else the operator's)
        when it differs from the one in use by more than 2 %."""
        d = (
            self._self_cal_est.target_diameter_m
            if gains.k_selfcal >= 0.5
            else self._dkf_belief.target_diameter_m
        )
        c = self.dkf.config
        if abs(d / c.target_diameter_m - 1.0) > 0.02:
            self.dkf.config = dataclasses.replace(c, target_diameter_m=d)

    # ------------------------------------------------------------------ the tick
    def tick(
        self, state: VehicleState, brake: bool = False, hold_s: float | None = None
    ) -> ControlTelemetry:
        """One control tick at ``state.time_s``; with ``brake`` the estimate keeps running but
        the command brakes and holds (an operator abort).

        ``hold_s``: how long this command will be held, until the next tick (s). Eq. 17's dt
        and the per-command terms (speed ramp, pursuit, midcourse) take the hold; the DKF's
        prediction and the LOS low-pass take the time elapsed since the last tick. A tick
        sooner than the last command's hold cut that command short: the part of its LOS
        change not flown (the fraction of its hold left) is added to this one's; a tick later
        than the hold let it turn too far: the excess (the fraction beyond the hold, at most
        one hold's worth) is taken off this one's, so the turn summed over the commands stays
        K times the LOS change (with the low-pass on, the LOS change is filtered as a rate
        instead, over the elapsed time, per hold). None: the hold is the elapsed time, as on a
        fixed grid (the simulator: nothing else changes). The runtime passes the time until
        its next tick is expected (its next deadline plus the recent wake-up lateness)."""
        t = state.time_s
        if self._pending_gains is not None:
            self.gains, self._pending_gains = self._pending_gains, None
            g = self.gains
            self.disturbance.set_bandwidth(g.k_dob, g.a_max, g.k_drag)
            self.dkf.carry_max_s = g.t_carry
            self.own_velocity.set_time_constant(g.tau_vel)
            self._use_size(g)
        gains = self.gains
        dt = self.nominal_dt_s if self._prev_time_s is None else t - self._prev_time_s
        if not dt > 0.0:
            dt = self.nominal_dt_s
        hold = dt if hold_s is None or not hold_s > 0.0 else hold_s

        gyro = self.gyro_turn.mean_rate(state.body_rates_flu_rad_s)
        q = as_quat(state.attitude_wxyz)
        if gains.t_att_lag > 0.0:
            R_WB = propagate_rotation(rotmat_of_quat(q), gyro, gains.t_att_lag)
            R_WC = mat3_mul(R_WB, self._R_BC)
        else:
            R_WB, R_WC = body_and_camera_attitude(q, self._R_BC)
        z0, z1, z2 = R_WB[:, 2].tolist()  # the thrust axis, body z in ENU
        v_est = state.velocity_enu_m_s
        v = v_est
        v0, v1, v2 = v_est.tolist()
        vf = (v0, v1, v2)  # v as floats
        lag = gains.t_vel_lag
        if lag > 0.0:
            # the velocity estimate is t_vel_lag old: add the acceleration since, from the
            # thrust last commanded along the thrust axis, gravity and the observer's d^ (in
            # floats: numpy's elementwise operations, in the same order, to the bit)
            k = self._thrust_n / self.vehicle.mass_kg
            a0, a1, a2 = z0 * k, z1 * k, z2 * k - GRAVITY_M_S2
            if self.disturbance.enabled:
                d0, d1, d2 = self.disturbance.estimate_floats
                a0, a1, a2 = a0 + d0, a1 + d1, a2 + d2
            vf = (v0 + lag * a0, v1 + lag * a1, v2 + lag * a2)
            v = np.array(vf)
        # the DKF's own velocity, complementary-filtered (estimation/own_velocity.py)
        v_cam = self.own_velocity.update(dt, *vf)
        v_cam = np.array(v_cam) if gains.tau_vel > 0.0 else v
        ladder = self.ladder
        ladder.on_tick(t, R_WC)
        ox, oy, oz = self._offset_b_m
        if ox or oy or oz:
            # the camera's own velocity: the body's plus omega x the believed mount offset
            w0, w1, w2 = (float(c) for c in gyro)
            c0, c1, c2 = w1 * oz - w2 * oy, w2 * ox - w0 * oz, w0 * oy - w1 * ox
            v_cam = v_cam + R_WB @ np.array((c0, c1, c2))
        self.dkf.predict(t, gyro, v_cam, R_WC)
        self.self_cal.on_tick(t, gyro, v_cam, self._los_prev)
        self.last_fusion, self._fused_early = self._fused_early, []
        if self._detections:
            dets = sorted(self._detections, key=lambda d: d.capture_time_s)
            self._detections.clear()
            if ladder.screening(t):
                dets = ladder.screened(dets, R_WC, gains)
            for det in dets:
                self.last_fusion.append(self._fuse(det))

        dob = self.disturbance
        finite = math.isfinite  # the observer's input check (DisturbanceObserver.update)
        if finite(v0) and finite(v1) and finite(v2) and finite(z0) and finite(z1) and finite(z2):
            d_hat = dob.update_floats(t, (v0, v1, v2), (z0, z1, z2))
        else:
            d_hat = dob.estimate_floats
        # the drag the loop believes (its airframe's in still air, the rotor-plane model) and
        # the observer's estimate of the rest: the speed ramp overcomes its along-track part,
        # the attitude loop cancels the part across the velocity
        d_hat = believed_drag_floats(v0, v1, v2, z0, z1, z2, *d_hat, gains.k_drag)
        # the estimate, the buffered one at the last tick and the range: one read
        est, est_prev_e, est_range = self.dkf.view(self._prev_time_s)
        motion = None
        if self.motion is not None:
            motion = self._track_motion(t, est, state, R_WB, gyro)
        e_est = e_rate = None
        q_y = q_z = s_y = s_z = math.nan
        yaw_rate = 0.0
        mode = ladder.next_mode(t, est, v, gains)
        self.mode = mode
        a_up = upward_accel_m_s2(self.vehicle.hover_thrust_normalised, gains.k_up)
        alt = float(state.position_enu_m[2])
        if brake:
            mode = LoopMode.BRAKE
        if mode is not LoopMode.TRACKING and mode is not LoopMode.COAST:
            self._dq_filt = _NAN2
            self._dq_flown = _NO_FLOWN
            self._los_prev = None  # no line of sight for the size estimate's displacement
            self._target_low_m = -math.inf
            self.speed_cap_m_s = math.inf
        if mode is LoopMode.REACQUIRE:
            e_est, e_rate = est.e_px, est.e_rate_px_s
            f = self.camera.f_px
            n_t = line_of_sight(e_est[0] / f, e_est[1] / f, R_WC)
            q_y, q_z = direction_angles(n_t)
            a_d = reacquire_accel(n_t, v, gains, self.fov_edges_rad)
            e_lat_px = self.camera.upright(*e_est)[0]
            e_lat_rate_px_s = self.camera.upright(*e_rate)[0]
            yaw_rate = yaw_rate_command(e_lat_px, e_lat_rate_px_s, gains)
        elif mode is LoopMode.SEARCH:
            a_d = search_accel(
                ladder.search_cue, v, gains, ladder.last_los(state.position_enu_m),
                self.fov_edges_rad,
            )  # fmt: skip
            yaw_rate = search_yaw_rate(
                ladder.search_cue, R_WC[:, 2], ladder.search_dir, gains, t - ladder.search_start_s
            )
        elif mode is not LoopMode.TRACKING and mode is not LoopMode.COAST:
            a_d = brake_accel(v, gains, a_up)  # brake and hold
            if est is not None and not est.lost:
                e_est, e_rate = est.e_px, est.e_rate_px_s
        else:  # tracking, or coasting on the prediction: the guidance law
            e_est, e_rate = est.e_px, est.e_rate_px_s
            f = self.camera.f_px
            # the previous LOS from the replay-corrected buffered estimate: a fused detection
            # moves both ends of the difference, so Delta q carries no correction jump
            prev = est_prev_e
            R_prev = self._prev_R_WC
            has_prev = prev is not None and R_prev is not None
            if not has_prev:
                prev, R_prev = (0.0, 0.0), R_WC
            elif self.gyro_turn.through_gyro(state, R_WB, gyro, dt):
                # the body's turn since the last tick is the gyro's, not the difference of
                # two attitude estimates (their corrections, a stale attitude replaced), which
                # PNG would turn K times within one command
                R_prev = mat3_mul(propagate_rotation(R_WB, gyro, -dt), self._R_BC)
            fy, fz = self._dq_filt
            ly, lz, lh = self._dq_flown
            n0, n1, n2, q_y, q_z, dq_y, dq_z, fy, fz, ly, lz, lh = los_terms(
                e_est[0], e_est[1], f, R_WC, has_prev, prev[0], prev[1], R_prev, dt, hold,
                hold_s is not None, gains.tau_los, fy, fz, ly, lz, lh, MAX_LATE_CARRY,
            )  # fmt: skip
            self._dq_filt, self._dq_flown = (fy, fz), (ly, lz, lh)
            self._los_prev = np.array((n0, n1, n2))
            if ladder.confirmed and est_range is not None and math.isfinite(est_range):
                # where a search after a loss looks
                ladder.last_target_enu_m = state.position_enu_m + est_range * self._los_prev
            e_n = (e_est[0] / f, e_est[1] / f)
            range_m, v_t, var_v = math.nan, None, math.nan
            # the approach's speed near the ground (control/clearance.py)
            dv = self.dkf.depth_velocity()
            v_cap, self._target_low_m = track_speed_cap_m_s(
                self._target_low_m, dt, alt, (n0, n1, n2), vf, e_n, dv, a_up, gains
            )
            self.speed_cap_m_s = v_cap
            mean_range = est_range if gains.tau_zem > 0.0 else None
            # within r_mid the midcourse weight is 0 whatever the covariance: skip computing it
            if mean_range is not None and mean_range > gains.r_mid and dv is not None:
                # the range the DKF is confident of: its inverse depth one sigma high
                # (a poorly known depth must not switch the midcourse term on)
                rng, v_t, P = dv
                range_m = range_interval_m(rng, e_n, float(P[2, 2]), sigmas=1.0)[0]
                var_v = float(P[3, 3] + P[4, 4] + P[5, 5])
            if self._law is png_law:  # the proposed law from the floats at hand (its own code)
                a0, a1, a2, s_y, s_z, _ = png_command(
                    hold, (n0, n1, n2), q_y, dq_y, dq_z, vf, R_WC, self.fov_edges_rad,
                    range_m, v_t, var_v, gains, d_hat, v_cap,
                )  # fmt: skip
                a_d = np.array((a0, a1, a2))
            else:
                out = self._law(
                    GuidanceInput(
                        *(hold, np.array((n0, n1, n2)), q_y, q_z, dq_y, dq_z, v, e_n, R_WC),
                        self.fov_edges_rad,
                        range_m=range_m,
                        target_vel_enu_m_s=v_t,
                        target_vel_var_m2_s2=var_v,
                        disturbance_enu_m_s2=d_hat,
                        target_accel_enu_m_s2=manoeuvre_accel_m_s2(
                            motion, gains.z_off, gains.z_full
                        ),
                        target_turn_rate_rad_s=0.0 if motion is None else motion.turn_rate_rad_s,
                        range_est_m=math.nan if est_range is None else est_range,
                        target_speed_m_s=math.nan if motion is None else motion.speed_m_s,
                        accel_limit_m_s2=available_lateral_accel_m_s2(
                            self.vehicle.hover_thrust_normalised, gains.tilt_max, gains.a_z_margin
                        ),
                        time_to_go_s=time_to_go_s(est_range, (n0, n1, n2), v, motion),
                        endgame_accel_limit_m_s2=available_lateral_accel_m_s2(
                            self.vehicle.hover_thrust_normalised, gains.tilt_end, gains.a_z_margin
                        ),
                        speed_cap_m_s=v_cap,
                    ),
                    gains,
                )
                a_d, s_y, s_z = out.accel_desired_enu_m_s2, out.vel_elev_rad, out.vel_azim_rad
            e_lat_px = self.camera.upright(*e_est)[0]
            e_lat_rate_px_s = self.camera.upright(*e_rate)[0]
            yaw_rate = yaw_rate_command(e_lat_px, e_lat_rate_px_s, gains)

        if mode is LoopMode.COAST or mode is LoopMode.REACQUIRE or mode is LoopMode.SEARCH:
            # without a live track: never descend below h_floor above home (z = 0)
            a_d = floor_guard_accel(a_d, alt, float(v[2]), gains)
        if mode is not LoopMode.WAITING:
            # a descent the believed airframe could not stop above h_clear is braked with its
            # upward capability (the pass of a low target and the brake after it)
            a_d = clearance_guard_accel(a_d, alt, float(v[2]), a_up, gains)

        # drag and disturbance feed-forward: the attitude loop flies a_d - D (D the believed
        # drag plus d^; its part normal to v in flight, the along-track part being the speed
        # ramp's; the guidance limit a_max applies to a_d, |d^| is clamped by the observer)
        ad0, ad1, ad2 = a_d.tolist()
        veh = self.vehicle
        d0, d1, d2 = d_hat
        # never hand a non-finite or out-of-range command on: the guard flies level hover
        w0, w1, w2, thrust, guard, a_normal = command_floats(
            ad0, ad1, ad2, dob.enabled or gains.k_drag > 0.0, d0, d1, d2, *vf, gains.v_min, R_WB,
            yaw_rate,
            gains.k_R, gains.omega_max, veh.mass_kg, veh.max_thrust_n,
            veh.hover_thrust_normalised,
        )  # fmt: skip
        guard = guard != 0.0
        if guard:
            self.guard_trips += 1
        self.disturbance.commanded(thrust)
        self._thrust_n = thrust * veh.max_thrust_n
        self.own_velocity.set_thrust(self._thrust_n / veh.mass_kg, z0, z1, z2, d0, d1, d2)
        self._prev_time_s = t
        self._prev_R_WC = R_WC
        self.gyro_turn.prev_R_WB = R_WB
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
            accel_normal_desired_m_s2=a_normal,
            yaw_rate_cmd_rad_s=yaw_rate,
            command=RateThrustCommand(t, np.array((w0, w1, w2)), thrust),
            dkf_time_since_detection_s=(math.inf if est is None else est.time_since_detection_s),
            dkf_lost=est is None or est.lost,
            guard_tripped=guard,
            self_cal=self._self_cal_est,
            target_accel_enu_m_s2=None if motion is None else motion.accel_enu_m_s2,
            motion_model_probs=None if motion is None else motion.probabilities,
            target_turn_rate_rad_s=None if motion is None else motion.turn_rate_rad_s,
            speed_cap_m_s=self.speed_cap_m_s,
        )
