"""The scenario's sections as typed dataclasses: their fields are the keys a scenario file
may hold, fields without a default are required, and the annotation gives the type. Angles are
degrees in the file and stay so named (``yaw_deg``); they are converted where used."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from onboard.gains import Gains

Vec3 = tuple[float, float, float]
MOTIONS = (
    "static", "cv", "ca", "sinusoid", "circle", "escape", "takeoff", "tethered", "balloon",
    "turn", "weave", "jink", "evade", "surge",
)  # fmt: skip
SCENARIO_DIR = Path(__file__).parent.parent / "scenarios"


CAMERA_MODES = ("projected", "rendered")  # how the simulated camera sees the target
ESTIMATE_PROFILES = ("indoor-mocap", "outdoor-gnss", "ideal", "table")  # sim/profiles.py


@dataclass(frozen=True)
class InterceptorSpec:
    position_m: Vec3
    velocity_m_s: Vec3 = (0.0, 0.0, 0.0)
    yaw_deg: float = 90.0  # heading of body x from +x toward +y
    size_m: float = 0.3  # diameter used for the hit test
    mass_kg: float = 1.5
    thrust_to_weight: float = 3.0
    rate_time_constant_s: float = 0.05
    thrust_time_constant_s: float = 0.03
    max_rate_deg_s: float = 229.18  # 4 rad/s
    # the airframe in the air (docs/air.md): drag on the air-relative velocity, true values
    # (the loop believes only its gains' k_drag), and the rotors' downwash
    drag_n_s_m: float = 0.0  # linear, every direction
    drag_area_m2: float = 0.02  # body C_d A: quadratic drag 0.5 rho C_d A |v_a| v_a
    rotor_drag_n_s_m: float = 0.2  # rotor (induced) drag at hover thrust, in the rotor plane
    # drawn per sortie when drag_max_n_s_m > 0: the drag at 10 m/s over 10 m/s uniform in
    # [min, max], its rotor share uniform in [0.3, 0.7] (the three fields above then unused)
    drag_min_n_s_m: float = 0.0
    drag_max_n_s_m: float = 0.0
    rotor_disc_area_m2: float = 0.16  # all rotors' discs (the downwash, momentum theory)


@dataclass(frozen=True)
class TargetSpec:
    motion: str
    position_m: Vec3  # start position (tethered: rest position)
    # cv, ca, sinusoid drift, escape start, takeoff climb; the manoeuvres' start velocity
    velocity_m_s: Vec3 = (0.0, 0.0, 0.0)
    acceleration_m_s2: Vec3 = (0.0, 0.0, 0.0)  # ca, escape
    amplitude_m: Vec3 = (0.0, 0.0, 0.0)  # sinusoid
    period_s: float = 0.0  # sinusoid, circle (negative: clockwise circle); weave, surge: least
    radius_m: float = 0.0  # circle
    max_speed_m_s: float = 30.0  # escape; evade from rest
    start_s: float = 0.0  # takeoff: climb starts at this time; turn: the turn starts
    # the manoeuvres (groundstation/sim/targets.py, docs/agility.md); ranges are drawn per
    # sortie, uniform between their ends
    lateral_accel_m_s2: float = 0.0  # turn (+ left, - right), evade (its size)
    period_max_s: float = 0.0  # weave, surge: the period's upper end (<= period_s: fixed)
    amplitude_min_m: float = 0.0  # weave: the sideways amplitude's range
    amplitude_max_m: float = 0.0
    trigger_range_m: float = 0.0  # jink; evade (0: from the start): the interceptor this near
    jink_speed_m_s: float = 2.5  # jink: the sideways speed of the dart
    jink_accel_m_s2: float = 8.0  # jink: its acceleration
    side: float = 0.0  # jink, evade: +1 left of the line of sight, -1 right, 0 drawn
    speed_change_m_s: float = 0.0  # surge: the speed's amplitude
    diameter_m: float = 0.3
    tether_length_m: float = 1.0  # tethered
    net_lift_n: float = 0.0  # tethered: buoyancy minus weight; 0 = from helium physics
    mass_kg: float = 0.0  # tethered: balloon, gas and added air mass; 0 = from physics
    envelope_mass_kg: float = 0.0015  # tethered: the latex (a ~0.16 m party balloon)
    drag_coefficient: float = 0.47  # tethered: sphere
    # a light target in the air (tethered, balloon: a free helium balloon; docs/air.md): the
    # vortex-shedding side force's coefficient amplitude (0: no buffet) and Strouhal number
    buffet_lift_coefficient: float = 0.1
    strouhal_number: float = 0.2


@dataclass(frozen=True)
class CameraSpec:
    width_px: int = 640
    height_px: int = 480
    hfov_deg: float = 90.0
    rate_hz: float = 30.0
    delay_s: float = 0.08  # capture to result
    delay_jitter_s: float = 0.005  # 1 sigma
    # projected mode's blob (docs/realism.md "Perception"): centre noise 1 sigma per axis
    # max(noise_px, centre_noise_k_px / sqrt(radius_px)), radius noise 1 sigma
    # hypot(size_noise_px, size_noise_rel x radius)
    noise_px: float = 0.3  # the centre noise's floor (a large blob's)
    centre_noise_k_px: float = 1.0  # px^1.5: 1 px at a 1 px radius, 0.5 px at 4 px
    size_noise_px: float = 0.3
    size_noise_rel: float = 0.03
    dropout_probability: float = 0.02
    mount_pitch_deg: float = 0.0
    mount_roll_deg: float = 0.0
    # detector faults (docs/realism.md); each 0 switches its part off
    min_blob_px: float = 3.2  # blobs narrower than this (diameter, px) are not detected
    false_probability: float = 0.01  # per frame: a false red blob (clutter) is detected
    false_blob_px: float = 5.0  # diameter of a false blob; the larger blob wins the frame
    burst_probability: float = 0.02  # per frame: a good frame starts a drop burst
    burst_mean_frames: float = 5.0  # mean burst length (frames), geometric
    burst_drop_probability: float = 1.0  # drop probability inside a burst
    # the true lens and mount (docs/realism.md); the loop knows them only through the
    # operator's calibration in [belief]
    principal_offset_u_px: float = 2.5  # principal point right of the image centre
    principal_offset_v_px: float = -1.5  # principal point below the image centre
    k1: float = -0.105  # Brown-Conrady radial (OpenCV's distCoeffs order k1, k2, p1, p2)
    k2: float = 0.012
    p1: float = 0.0004  # tangential
    p2: float = -0.0003
    offset_m: Vec3 = (0.08, 0.0, 0.03)  # camera from the centre of mass, body FLU


WIND_MODELS = ("uniform", "jet")  # groundstation/sim/wind.py


@dataclass(frozen=True)
class WindSpec:
    mean_m_s: Vec3 = (0.0, 0.0, 0.0)  # jet: the wind at the target's rest position
    gust_m_s: float = 0.0  # 1 sigma per horizontal axis (vertical: 30 %); jet: at the target
    gust_time_constant_s: float = 2.0  # a gust's passing time (see turbulence_length_m)
    model: str = "uniform"  # uniform | jet (a fan's round jet along mean_m_s)
    jet_source_m: Vec3 = (0.0, 0.0, 0.0)  # jet: the fan's outlet centre
    jet_diameter_m: float = 0.5  # jet: the fan's outlet diameter
    # turbulence (docs/air.md): the von Karman field's longitudinal integral length scale;
    # 0: gust_time_constant_s times the mean wind's speed (at least 1 m/s)
    turbulence_length_m: float = 0.0


@dataclass(frozen=True)
class SimSpec:
    physics_rate_hz: int = 600
    control_rate_hz: int = 100
    gyro_noise_rad_s: float = 0.003


@dataclass(frozen=True)
class EstimateSpec:
    """What the loop is handed instead of the truth (``groundstation/sim/estimate.py`` gives
    the model and the sources of each default). Sigmas are 1-sigma per axis."""

    enabled: bool = True  # false: ideal sensors (the loop sees the truth)
    # the named error profile drawn per sortie (groundstation/sim/profiles.py): it draws every
    # key below left at its default; "table" flies the keys as written, "ideal" the truth
    profile: str = "outdoor-gnss"
    heading_noise_deg: float = 0.2  # the attitude error about body z (others: att_noise_deg)
    pos_noise_m: float = 0.05  # Gauss-Markov position error
    pos_time_constant_s: float = 2.0
    vel_noise_m_s: float = 0.05  # Gauss-Markov velocity error
    vel_time_constant_s: float = 1.0
    att_noise_deg: float = 0.2  # Gauss-Markov attitude error (small rotation, body axes)
    att_time_constant_s: float = 2.0
    lag_s: float = 0.02  # the position and velocity estimates are the vehicle this long ago
    att_lag_s: float = 0.01  # the attitude estimate is the vehicle this long ago
    gyro_bias_rad_s: float = 0.003  # turn-on bias left after calibration
    gyro_bias_walk_rad_s_sqrt_s: float = 0.0001  # bias random walk
    camera_time_offset_s: float = 0.005  # camera-IMU stamp offset, drawn once a sortie
    camera_stamp_jitter_s: float = 0.001  # per frame, on top of the offset
    thrust_scale_sigma: float = 0.02  # true / modelled thrust, drawn once a sortie
    command_delay_s: float = 0.005  # command to actuators (MAVLink + PX4 scheduling)


@dataclass(frozen=True)
class BeliefSpec:
    """What the vehicle's operator believes: the loop is configured from this table and
    [gains] only, never from the true values of the other tables (docs/realism.md). Each
    default is the operator's parameter's default (``PRG_TGT_DIAM``, ``PRG_CAM_HFOV``, ...) or
    a typical calibration of the default camera, independent of the scenario's truth."""

    target_diameter_m: float = 0.3  # PRG_TGT_DIAM
    camera_hfov_deg: float = 90.0  # PRG_CAM_HFOV: the calibrated focal length
    camera_mount_pitch_deg: float = 0.0  # PRG_CAM_PITCH
    camera_mount_roll_deg: float = 0.0  # PRG_CAM_ROLL
    camera_principal_offset_u_px: float = 0.0  # calibrated principal point from the centre
    camera_principal_offset_v_px: float = 0.0
    camera_k1: float = -0.1  # calibrated Brown-Conrady coefficients
    camera_k2: float = 0.01
    camera_p1: float = 0.0
    camera_p2: float = 0.0
    camera_offset_m: Vec3 = (0.08, 0.0, 0.03)  # measured camera offset from the CoM, FLU
    hover_thrust: float = 1.0 / 3.0  # PRG_HOVER_THR: normalised thrust that hovers
    # PRG_TGT_ACC: the DKF's random walk of the target's velocity (m/s^2 per sqrt(Hz)), which
    # also carries the vehicle's velocity-estimate errors: 6 on GNSS, 1 on motion capture
    target_accel_noise_m_s2: float = 6.0


@dataclass(frozen=True)
class Scenario:
    name: str
    duration_s: float
    interceptor: InterceptorSpec
    target: TargetSpec
    description: str = ""
    camera: CameraSpec = field(default_factory=CameraSpec)
    wind: WindSpec = field(default_factory=WindSpec)
    sim: SimSpec = field(default_factory=SimSpec)
    estimate: EstimateSpec = field(default_factory=EstimateSpec)
    belief: BeliefSpec = field(default_factory=BeliefSpec)
    gains: dict[str, float] = field(default_factory=dict)
    source: str = "<memory>"
    text: str = ""  # the file as read, for recording alongside a sortie

    def gains_obj(self) -> Gains:
        return Gains.from_mapping(self.gains, source=f"{self.source}: [gains]")


SECTIONS = {
    "interceptor": InterceptorSpec,
    "target": TargetSpec,
    "camera": CameraSpec,
    "wind": WindSpec,
    "sim": SimSpec,
    "estimate": EstimateSpec,
    "belief": BeliefSpec,
}
