"""One simulated sortie: the multicopter, target, wind and camera advanced on one clock of
integer physics steps, with the onboard :class:`~onboard.loop.InterceptionLoop` in the loop.

Each physics step k (time k / physics_rate) does, in order: capture a frame if due, run the
control tick if due (deliver ready detections and the gyro sample, apply the command), then
integrate vehicle, target and wind to step k + 1 and check the outcome. The closest approach
is found in continuous time inside every step (relative motion linear over the step).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence

import numpy as np

from onboard.datatypes import ControlTelemetry, Detection, GyroSample, VehicleState
from onboard.enums import DEFAULT_LAW, LoopMode, Outcome
from onboard.estimation.dkf import FusionResult
from onboard.frames import Frame, SortieObserver, SortieStart
from onboard.gains import Gains
from onboard.geometry import as_quat, camera_attitude, rotmat_of_quat
from onboard.link.params import RuntimeParams
from onboard.loop import InterceptionLoop
from onboard.track_loss import intercept_over

from ..scenario import Scenario, scenario_toml
from .beliefs import loop_configuration, true_camera
from .camera import SimCamera
from .estimate import StateEstimateModel
from .outcome import (
    OUTCOME_OF_CODE,
    RECOVERY_TIMEOUT_S,
    SortieResult,
    has_recovered,
)
from .physics import (
    C_CLOSE_REL,
    C_CLOSE_VEL,
    C_HIT_R,
    C_MIN_ALT,
    C_MISS,
    C_OUTCOME,
    C_PASS,
    C_PASS_TIME,
    C_REL,
    C_SIZE,
    C_SPEED,
    C_TIME,
    C_TWO,
    S_CMD,
    S_CS,
    normal_accel,
    physics_steps,
    sortie_buffer,
)
from .profiles import profile_of, sortie_estimate
from .random_processes import Normals
from .targets import Target, TrackTarget
from .vehicle import Multicopter
from .wind import Wind

_STALE_MODES = (LoopMode.COAST, LoopMode.REACQUIRE, LoopMode.SEARCH)


class Simulation:
    def __init__(
        self,
        scenario: Scenario,
        law: str = DEFAULT_LAW.value,
        seed: int = 0,
        camera_mode: str = "projected",
        gains: Gains | None = None,
        keep_records: bool = True,
        observers: Sequence[SortieObserver] = (),
        target_track: tuple[list[float], list[tuple[float, float, float]]] | None = None,
        records_dkf: bool = True,
    ) -> None:
        """``records_dkf = False``: frames made only for :attr:`records` (no observers) leave
        the DKF's image state and covariance diagonal None (the campaigns' traces do not read
        them; computing them propagates the covariance every tick). What is flown is the
        same either way."""
        self.scenario = scenario
        self.law = law
        self.seed = int(seed)
        sim = scenario.sim
        self.dt_s = 1.0 / sim.physics_rate_hz
        self._control_div = round(sim.physics_rate_hz / sim.control_rate_hz)
        self._camera_div = round(sim.physics_rate_hz / scenario.camera.rate_hz)
        for name, div, rate in (
            ("control", self._control_div, sim.control_rate_hz),
            ("camera", self._camera_div, scenario.camera.rate_hz),
        ):
            if abs(div * rate - sim.physics_rate_hz) > 1e-9:
                raise ValueError(f"{name} rate {rate} Hz must divide {sim.physics_rate_hz} Hz")
        ss = np.random.SeedSequence(self.seed)
        cam_rng, wind_rng, gyro_rng, render_rng = (np.random.default_rng(s) for s in ss.spawn(4))
        self._gyro_noise = Normals(gyro_rng, 3)  # the gyro's white noise, drawn in blocks
        # the estimate model's streams are the next child: the four above stay as they were
        est_seed = ss.spawn(1)[0]
        # the error profile's draw for this sortie (the next child: the streams above stay)
        self.profile = profile_of(scenario)
        self.estimate_spec = spec = sortie_estimate(scenario, ss.spawn(1)[0])
        self.estimate = None if spec is None else StateEstimateModel(spec, est_seed)
        self._command_delay_steps = (
            0 if self.estimate is None else round(self.estimate.command_delay_s / self.dt_s)
        )
        self._commands: deque = deque()  # (physics step due, body rates, thrust) in flight
        c = scenario.camera
        self.camera_model = true_camera(scenario)  # the camera as it is (the loop's: belief)
        self._R_BC = np.array(self.camera_model.R_BC)  # writable, as the kernels take it
        # the airframe's drawn drag (where the scenario gives a range) and a light target's
        # buffet phase: their own streams
        air_rng, target_rng = (np.random.default_rng(s) for s in ss.spawn(2))
        self.vehicle = Multicopter(scenario.interceptor, air_rng)
        self.target = (
            Target(scenario.target, target_rng)
            if target_track is None
            else TrackTarget(scenario.target, *target_track)
        )
        self.wind = Wind(scenario.wind, wind_rng, scenario.target.position_m)
        self.target.settle_in_wind(self.wind.mean_at)
        self.camera = SimCamera(c, self.camera_model, camera_mode, cam_rng, render_rng)
        # the loop is built from what the vehicle believes, never from the truth
        self.loop_config = cfg = loop_configuration(scenario, law, gains)
        self.loop = InterceptionLoop(
            cfg.camera,
            cfg.vehicle,
            cfg.gains,
            law=cfg.law,
            control_rate_hz=cfg.control_rate_hz,
            dkf_config=cfg.dkf,
            # the IMM's estimate in frames that show the filter (campaigns' traces do not)
            estimate_motion=records_dkf and (keep_records or bool(observers)),
        )
        self.hit_radius_m = 0.5 * (scenario.target.diameter_m + scenario.interceptor.size_m)
        self.step_index = 0
        self.outcome: Outcome | None = None
        self.keep_records = keep_records
        self.records_dkf = records_dkf
        self.records: list[Frame] = []  # every control tick's frame, if keep_records
        self.last_telemetry: ControlTelemetry | None = None
        self.last_detection: Detection | None = None  # latest delivered (delayed) detection
        tp, vp = self.target.p, self.vehicle.p
        rel = (tp[0] - vp[0], tp[1] - vp[1], tp[2] - vp[2])
        self.initial_range_m = math.sqrt(sum(c * c for c in rel))
        # vehicle, target, wind, closest approach and outcome in one array for the kernel
        self._physics = sortie_buffer(self.vehicle, self.target, self.wind, self.dt_s)
        self.closest = cs = self._physics[S_CS : S_CS + C_SIZE]  # C_* layout
        cs[C_REL : C_REL + 3] = cs[C_CLOSE_REL : C_CLOSE_REL + 3] = rel
        cs[C_MISS] = self.initial_range_m
        cs[C_CLOSE_VEL : C_CLOSE_VEL + 3] = self.vehicle.v
        cs[C_HIT_R], cs[C_TWO] = self.hit_radius_m, 2.0
        self.max_normal_accel_m_s2 = 0.0
        self.normal_accel_m_s2 = 0.0
        self._fused = self._rejected = 0
        # the onboard rule that ends an intercept (the runtime's state machine): the largest
        # blob's width fraction while tracking, and whether the loop now brakes and holds
        self._done_size_frac = RuntimeParams().DONE_SIZE
        self._max_size_frac = 0.0
        self.braking = False
        self.recovered = False
        self.observers = list(observers)
        self.finished = False  # observers told the end
        if self.observers:
            info = self.start_info()
            for o in self.observers:
                o.start(info)

    # ------------------------------------------------------------------ helpers
    @property
    def time_s(self) -> float:
        return self.step_index * self.dt_s

    @property
    def miss_m(self) -> float:
        """Closest approach so far (m)."""
        return float(self.closest[C_MISS])

    @miss_m.setter
    def miss_m(self, value: float) -> None:
        self.closest[C_MISS] = value

    @property
    def closest_time_s(self) -> float:
        return float(self.closest[C_TIME])

    @property
    def closest_speed_m_s(self) -> float:
        """The vehicle's speed at the closest approach (m/s)."""
        return float(self.closest[C_SPEED])

    @property
    def closest_rel_m(self) -> tuple[float, float, float]:
        """Target minus vehicle at the closest approach (m, ENU)."""
        return tuple(self.closest[C_CLOSE_REL : C_CLOSE_REL + 3].tolist())

    @property
    def closest_vel_m_s(self) -> tuple[float, float, float]:
        """The vehicle's velocity at the closest approach (m/s, ENU)."""
        return tuple(self.closest[C_CLOSE_VEL : C_CLOSE_VEL + 3].tolist())

    @property
    def done(self) -> bool:
        return self.outcome is not None

    def R_WC(self) -> np.ndarray:
        return camera_attitude(as_quat(self.vehicle.q), self._R_BC)

    def start_info(self) -> SortieStart:
        sc = self.scenario
        return SortieStart(
            scenario=sc.name,
            law=self.law,
            seed=self.seed,
            camera=self.camera.mode,
            camera_model=self.camera_model,
            target_diameter_m=sc.target.diameter_m,
            control_rate_hz=sc.sim.control_rate_hz,
            gains=self.loop.gains,
            scenario_source=sc.source,
            scenario_toml=scenario_toml(sc),
            estimate_profile=self.profile,
        )

    def frame(self) -> Frame:
        """The sortie now: at a control tick, what that tick computed; between ticks, the
        truth now with the last tick's loop output."""
        veh, loop = self.vehicle, self.loop
        state = loop.dkf.state_vector() if self.records_dkf or self.observers else None
        return Frame(
            time_s=self.time_s,
            vehicle_p_enu_m=tuple(veh.p),
            vehicle_q_wxyz=tuple(veh.q),
            vehicle_v_enu_m_s=tuple(veh.v),
            target_p_enu_m=tuple(self.target.p),
            telemetry=self.last_telemetry,
            normal_accel_m_s2=None if self.last_telemetry is None else self.normal_accel_m_s2,
            detection=self.last_detection,
            dkf_state_px=None if state is None else tuple(state[0].tolist()),
            dkf_cov_diag=None if state is None else tuple(state[1].tolist()),
            acquired=loop.ladder.acquired,
            gains=loop.gains,
            guard_trips=loop.guard_trips,
        )

    # ------------------------------------------------------------------ stepping
    def step(self) -> None:
        """Advance one physics step (running the camera and control events due now)."""
        if self.outcome is not None:
            return
        k = self.step_index
        t = k * self.dt_s
        if k % self._camera_div == 0:
            self._capture(t)
        if k % self._control_div == 0:
            self._control_tick(t)
            if self._check_loop_outcome(t):
                self._tell_finish(None)
                return
        self._physics_steps(k, 1)
        if self.outcome is not None:
            self._tell_finish(None)

    def camera_position(self) -> list[float]:
        """Where the camera is (ENU, m): the centre of mass plus the true mount offset."""
        p = self.vehicle.p
        o0, o1, o2 = self.camera_model.offset_b_m
        if not (o0 or o1 or o2):
            return p
        R = rotmat_of_quat(as_quat(self.vehicle.q))
        return [p[i] + R[i, 0] * o0 + R[i, 1] * o1 + R[i, 2] * o2 for i in range(3)]

    def _capture(self, t: float) -> None:
        self.camera.capture(
            t, self.R_WC(), self.camera_position(), self.target.p, self.scenario.target.diameter_m
        )
        for o in self.observers:
            o.image(t, self.camera.last_frame)

    def _physics_steps(self, k0: int, n: int) -> None:
        """Integrate vehicle, target and wind from step k0 over ``n`` steps (no camera frame
        or control tick due in between), checking the outcome after each and stopping at
        one: :func:`.physics.physics_steps`, one call unless two commands arrive within
        the ``n`` steps."""
        cmds = self._commands
        buf = self._physics
        modes = self.wind.modes
        track = self.target.track
        k, end = k0, k0 + n
        while True:
            # commands reach the actuators after their latency: the latest one due now, else
            # the next one due within these steps, goes to the kernel
            cmd = None
            while cmds and cmds[0][0] <= k:
                cmd = cmds.popleft()
            if cmd is None and cmds and cmds[0][0] < end:
                cmd = cmds.popleft()
            if cmd is not None:
                due, rates, thrust = cmd
                buf[S_CMD] = max(due, k)
                buf[S_CMD + 1], buf[S_CMD + 2], buf[S_CMD + 3] = rates[0], rates[1], rates[2]
                buf[S_CMD + 4] = thrust
            m = cmds[0][0] - k if cmds and cmds[0][0] < end else end - k
            taken = physics_steps(k, m, buf, track, modes)
            k += taken
            code = buf[S_CS + C_OUTCOME]
            if code != 0.0:
                self.outcome = OUTCOME_OF_CODE[int(code)]
                break
            if k >= end:
                break
        self.step_index = k

    def _as_the_runtime_hands_it(self, t: float) -> np.ndarray:
        """The control tick's gyro sample and estimated state at ``t`` as ``onboard run``
        hands them to the loop (:func:`.estimate.hand_off`, one kernel): the gyro the mean
        body rate since the last tick with its white noise and bias; position and velocity
        ``estimate.lag_s`` old, used unstamped (``gains.t_vel_lag``); the attitude PX4
        stamped ``estimate.att_lag_s`` before the tick, carried to it with that gyro sample
        as ``fc_state.vehicle_state_at`` does. Returns gyro (3), position, velocity,
        attitude (w, x, y, z), body rates and the attitude's time (17 floats)."""
        noise = self._gyro_noise.next()
        return self.estimate.hand_off(t, self.vehicle.x, noise, self.scenario.sim.gyro_noise_rad_s)

    def _control_tick(self, t: float) -> None:
        veh = self.vehicle
        loop = self.loop
        est = self.estimate
        for det in self.camera.deliver(t):
            if est is not None:
                det = est.stamp(det)
            loop.on_detection(det)
            self.last_detection = det
            if loop.mode is LoopMode.TRACKING:
                frac = det.bbox_px[2] / self.camera_model.width_px
                self._max_size_frac = max(self._max_size_frac, frac)
        brake = self.braking
        if est is None:
            sigma = self.scenario.sim.gyro_noise_rad_s
            (r0, r1, r2), (n0, n1, n2) = veh.read_gyro(), self._gyro_noise.next()
            rates = [r0 + n0 * sigma, r1 + n1 * sigma, r2 + n2 * sigma]
            loop.on_gyro(GyroSample(t, np.array(rates)))
            tel = loop.tick(veh.state(t), brake)
        else:
            h = self._as_the_runtime_hands_it(t)
            loop.on_gyro(GyroSample(t, h[0:3]))
            state = VehicleState(t, h[3:6], h[6:9], h[9:13], h[13:16], float(h[16]))
            tel = loop.tick(state, brake)
        if not brake:
            mode = loop.mode
            over = intercept_over(
                self._max_size_frac,
                self._done_size_frac,
                mode in _STALE_MODES,
                mode is LoopMode.LOST,
            )
            self.braking = over is not None
        for r in loop.last_fusion:
            if r is FusionResult.ACCEPTED or r is FusionResult.INITIALISED:
                self._fused += 1
            else:
                self._rejected += 1
        if est is None:
            veh.command(tel.command.body_rates_flu_rad_s, tel.command.thrust_normalised)
        else:
            self._commands.append(
                (
                    self.step_index + self._command_delay_steps,
                    tel.command.body_rates_flu_rad_s,
                    tel.command.thrust_normalised * est.thrust_scale,
                )
            )
        a_n, vv = normal_accel(veh.x)
        self.normal_accel_m_s2 = a_n  # actual, normal to the velocity, at this tick
        if vv > 0.25 and a_n > self.max_normal_accel_m_s2:
            self.max_normal_accel_m_s2 = a_n
        self.last_telemetry = tel
        if self.observers or self.keep_records:  # frames cost only when someone reads them
            frame = self.frame()
            for o in self.observers:
                o.frame(frame)
            if self.keep_records:
                self.records.append(frame)

    @property
    def passed(self) -> bool:
        """Has the pass happened (the sortie now waits for the recovery)?"""
        return self.closest[C_PASS] != 0.0

    def _check_loop_outcome(self, t: float) -> bool:
        """Outcomes that can only change at a control tick: after the pass, recovered (or
        out of recovery time); before it, target lost, never acquired, out of time."""
        cs = self.closest
        if cs[C_PASS] != 0.0:
            veh = self.vehicle
            self.recovered = has_recovered(veh.p, veh.v, veh.q)
            if self.recovered or t - cs[C_PASS_TIME] >= RECOVERY_TIMEOUT_S - 1e-9:
                self.outcome = OUTCOME_OF_CODE[int(cs[C_PASS])]
            return self.outcome is not None
        # a balloon bursts on contact: losing it from the image with the vehicle already on
        # it ends a hit (the pass completes in the physics), not a lost target
        contact = self.miss_m <= self.hit_radius_m
        # the loop coasts, re-acquires and searches; it gives up in its failsafe (lost)
        lost = self.loop.mode is LoopMode.LOST
        if lost and not contact:
            self.outcome = Outcome.TARGET_LOST
        elif t >= self.scenario.duration_s - 1e-9:
            self.outcome = Outcome.HIT if contact else Outcome.TIMEOUT
        return self.outcome is not None

    def _tell_finish(self, reason: str | None) -> None:
        if self.finished:
            return
        self.finished = True
        summary = None if self.outcome is None else self.result().to_json_dict()
        for o in self.observers:
            o.finish(self.time_s, summary, reason)

    def close(self, reason: str) -> None:
        """Tell the observers a sortie stopped before its outcome ends here (operator reset):
        a recording keeps it, marked INCOMPLETE with the reason."""
        self._tell_finish(reason)

    def step_control_period(self) -> None:
        """Advance to the next control tick (or the end)."""
        for _ in range(self._control_div):
            if self.outcome is not None:
                return
            self.step()

    def run(self) -> SortieResult:
        """Run to the outcome. The same events in the same order as calling :meth:`step`
        until done, scheduled by control period: a camera frame or control tick where one is
        due, and between ticks only physics steps."""
        cam_div, ctl_div, dt = self._camera_div, self._control_div, self.dt_s
        physics = self._physics_steps
        while self.outcome is None:
            k = self.step_index
            t = k * dt
            if k % cam_div == 0:
                self._capture(t)
            if k % ctl_div == 0:
                self._control_tick(t)
                if self._check_loop_outcome(t):
                    break
            # physics steps up to the next control tick or camera frame
            physics(k, min(ctl_div - k % ctl_div, cam_div - k % cam_div))
        self._tell_finish(None)
        return self.result()

    def result(self) -> SortieResult:
        if self.outcome is None:
            raise RuntimeError("the sortie has not ended")
        return SortieResult(
            outcome=self.outcome.value,
            miss_m=self.miss_m,
            intercept_time_s=self.closest_time_s,
            terminal_speed_m_s=self.closest_speed_m_s,
            max_normal_accel_m_s2=self.max_normal_accel_m_s2,
            law=self.law,
            seed=self.seed,
            scenario=self.scenario.name,
            camera=self.camera.mode,
            sim_time_s=self.time_s,
            hit_radius_m=self.hit_radius_m,
            detections_fused=self._fused,
            detections_rejected=self._rejected,
            guard_trips=self.loop.guard_trips,
            profile=self.profile,
            recovered=self.recovered,
            min_alt_after_pass_m=float(self.closest[C_MIN_ALT]) if self.passed else math.nan,
        )


def run_sortie(
    scenario: Scenario,
    law: str = DEFAULT_LAW.value,
    seed: int = 0,
    camera_mode: str = "projected",
    gains: Gains | None = None,
    observers: Sequence[SortieObserver] = (),
) -> SortieResult:
    """Run one sortie to its outcome (observed by ``observers``: a recorder, ...)."""
    sim = Simulation(
        scenario, law, seed, camera_mode, gains, keep_records=False, observers=observers
    )
    return sim.run()
