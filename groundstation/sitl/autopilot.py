"""The PX4 parts of the SITL vehicle that a PX4 user's tools look at, as pure pieces the
vehicle (:mod:`.vehicle`) wires to its link: the global position of a local ENU point around
a home, a battery, the sensor-health bits of ``SYS_STATUS``, the autopilot parameters (with
PX4's byte-wise INT32 encoding), the offset/clock of ``TIMESYNC`` answers and PX4's AUTO
modes (TAKEOFF, LAND, RTL).
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

from onboard.link.px4 import PX4_MAIN_AUTO, px4_custom_mode

EARTH_RADIUS_M = 6_378_137.0
PX4_SUB_AUTO_TAKEOFF, PX4_SUB_AUTO_RTL, PX4_SUB_AUTO_LAND = 2, 5, 6  # PX4's AUTO sub-modes
MODE_TAKEOFF = px4_custom_mode(PX4_MAIN_AUTO, PX4_SUB_AUTO_TAKEOFF)
MODE_LAND = px4_custom_mode(PX4_MAIN_AUTO, PX4_SUB_AUTO_LAND)
MODE_RTL = px4_custom_mode(PX4_MAIN_AUTO, PX4_SUB_AUTO_RTL)

# MAV_SYS_STATUS_SENSOR bits a healthy PX4 quadrotor reports present, enabled and healthy
SENSOR_BITS = {
    "3D_GYRO": 0x1,
    "3D_ACCEL": 0x2,
    "3D_MAG": 0x4,
    "ABSOLUTE_PRESSURE": 0x8,
    "GPS": 0x20,
    "ANGULAR_RATE_CONTROL": 0x400,
    "ATTITUDE_STABILIZATION": 0x800,
    "YAW_POSITION": 0x1000,
    "Z_ALTITUDE_CONTROL": 0x2000,
    "XY_POSITION_CONTROL": 0x4000,
    "MOTOR_OUTPUTS": 0x8000,
    "AHRS": 0x200000,
    "BATTERY": 0x2000000,
    "PREARM_CHECK": 0x10000000,
}
SENSORS_HEALTHY = sum(SENSOR_BITS.values())


@dataclass(frozen=True)
class Home:
    """Where local ENU (0, 0, 0) is on the Earth: latitude, longitude (deg), altitude AMSL (m)."""

    lat_deg: float = 47.397742  # PX4 SITL's default home (Zurich)
    lon_deg: float = 8.545594
    alt_m: float = 488.0

    def __post_init__(self) -> None:
        if not (-90.0 < self.lat_deg < 90.0 and -180.0 <= self.lon_deg <= 180.0):
            raise ValueError(f"home {self.lat_deg}, {self.lon_deg}: not a latitude/longitude")
        if not -500.0 <= self.alt_m <= 9000.0:
            raise ValueError(f"home altitude {self.alt_m} m AMSL: expected -500 to 9000")

    def to_global(self, p_enu_m) -> tuple[float, float, float]:
        """(lat deg, lon deg, alt m AMSL) of a local ENU point (flat Earth: metres to km)."""
        e, n, u = (float(c) for c in p_enu_m)
        lat = self.lat_deg + math.degrees(n / EARTH_RADIUS_M)
        lon = self.lon_deg + math.degrees(
            e / (EARTH_RADIUS_M * math.cos(math.radians(self.lat_deg)))
        )
        return lat, lon, self.alt_m + u


class Battery:
    """A lithium pack: open-circuit voltage falls linearly from 4.2 to 3.5 V per cell with
    the charge used, minus the current through an internal resistance; the current is an
    idle draw when armed plus a hover draw scaled by thrust^1.5 (power ~ thrust^1.5)."""

    def __init__(
        self,
        cells: int = 4,
        capacity_mah: float = 5000.0,
        hover_current_a: float = 18.0,
        idle_current_a: float = 0.8,
        resistance_ohm: float = 0.02,
    ) -> None:
        self.cells = cells
        self.capacity_mah = capacity_mah
        self.hover_current_a = hover_current_a
        self.idle_current_a = idle_current_a
        self.resistance_ohm = resistance_ohm
        self.consumed_mah = 0.0
        self.current_a = 0.0

    def step(self, dt_s: float, armed: bool, thrust_over_hover: float) -> None:
        if not armed:
            self.current_a = 0.0
        else:
            load = max(thrust_over_hover, 0.0) ** 1.5
            self.current_a = self.idle_current_a + self.hover_current_a * load
        self.consumed_mah += self.current_a * dt_s / 3.6

    @property
    def remaining(self) -> float:
        """State of charge, 0..1."""
        return max(0.0, 1.0 - self.consumed_mah / self.capacity_mah)

    @property
    def voltage_v(self) -> float:
        open_circuit = self.cells * (3.5 + 0.7 * self.remaining)
        return open_circuit - self.current_a * self.resistance_ohm

    @property
    def cell_voltages_mv(self) -> list[int]:
        """BATTERY_STATUS.voltages: one per cell, 65535 for the unused slots."""
        cell = round(1000.0 * self.voltage_v / self.cells)
        return [cell] * self.cells + [65535] * (10 - self.cells)


# ---------------------------------------------------------------------- parameters
PARAM_REAL32, PARAM_INT32 = 9, 6  # MAV_PARAM_TYPE


@dataclass(frozen=True)
class AutopilotParam:
    name: str
    default: float
    minimum: float
    maximum: float
    kind: int = PARAM_REAL32


AUTOPILOT_PARAMS: tuple[AutopilotParam, ...] = (
    AutopilotParam("COM_OF_LOSS_T", 1.0, 0.0, 60.0),  # offboard loss timeout, s
    AutopilotParam("COM_OBL_RC_ACT", 0, 0, 7, PARAM_INT32),  # then: 0 position (hold here)
    AutopilotParam("COM_RCL_EXCEPT", 4, 0, 7, PARAM_INT32),  # RC loss ignored in offboard
    AutopilotParam("COM_DISARM_LAND", 2.0, -1.0, 20.0),  # s on the ground before disarming
    AutopilotParam("MPC_XY_VEL_MAX", 12.0, 0.0, 20.0),  # m/s
    AutopilotParam("MPC_Z_VEL_MAX_UP", 3.0, 0.5, 8.0),  # m/s
    AutopilotParam("MPC_Z_VEL_MAX_DN", 1.5, 0.5, 4.0),  # m/s
    AutopilotParam("MPC_XY_VEL_P_ACC", 1.8, 1.2, 5.0),  # 1/s
    AutopilotParam("MPC_THR_HOVER", 0.5, 0.1, 0.8),  # set from the airframe at start
    AutopilotParam("MPC_TKO_SPEED", 1.5, 1.0, 5.0),  # m/s
    AutopilotParam("MPC_LAND_SPEED", 0.7, 0.6, 2.0),  # m/s
    AutopilotParam("MIS_TAKEOFF_ALT", 2.5, 0.0, 80.0),  # m above home
    AutopilotParam("RTL_RETURN_ALT", 30.0, 0.0, 150.0),  # m above home
    AutopilotParam("BAT1_N_CELLS", 4, 1, 14, PARAM_INT32),
    AutopilotParam("BAT1_CAPACITY", 5000.0, -1.0, 100000.0),  # mAh
    AutopilotParam("MAV_SYS_ID", 1, 1, 250, PARAM_INT32),
    AutopilotParam("SYS_AUTOSTART", 10016, 0, 9999999, PARAM_INT32),  # SITL quadrotor
)


def encode_value(value: float, kind: int) -> float:
    """A parameter value as PX4 puts it in PARAM_VALUE.param_value: REAL32 as is, INT32 as
    the float whose bytes are the integer's (MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE)."""
    if kind == PARAM_INT32:
        return struct.unpack("<f", struct.pack("<i", int(value)))[0]
    return float(value)


def decode_value(wire: float, kind: int) -> float:
    if kind == PARAM_INT32:
        return float(struct.unpack("<i", struct.pack("<f", wire))[0])
    return float(wire)


class AutopilotParams:
    """PX4's parameters the SITL honours or reports; a value out of range (or a wrong type)
    is refused and the old one stays, as PX4 does."""

    def __init__(self, **overrides: float) -> None:
        self.specs = {p.name: p for p in AUTOPILOT_PARAMS}
        self.order = [p.name for p in AUTOPILOT_PARAMS]
        self.values = {p.name: float(p.default) for p in AUTOPILOT_PARAMS}
        for name, value in overrides.items():
            if not self.set(name, value):
                raise ValueError(f"autopilot parameter {name} = {value}: out of range")

    def __getitem__(self, name: str) -> float:
        return self.values[name]

    def set(self, name: str, value: float) -> bool:
        spec = self.specs.get(name)
        if spec is None or not math.isfinite(value):
            return False
        if spec.kind == PARAM_INT32 and value != int(value):
            return False
        if not spec.minimum <= value <= spec.maximum:
            return False
        self.values[name] = float(value)
        return True

    def set_wire(self, name: str, wire: float, kind: int) -> bool:
        """A PARAM_SET: the value decoded as its declared type (the sender's type must match)."""
        spec = self.specs.get(name)
        if spec is None or kind != spec.kind:
            return False
        return self.set(name, decode_value(wire, kind))

    def wire(self, name: str) -> tuple[float, int]:
        spec = self.specs[name]
        return encode_value(self.values[name], spec.kind), spec.kind


def timesync_answer(tc1: int, ts1: int, now_s: float) -> tuple[int, int] | None:
    """PX4's answer to a TIMESYNC request: (tc1, ts1) with tc1 the vehicle's boot clock in
    nanoseconds at the request's arrival and ts1 echoed; ``None`` for a reply (tc1 != 0)."""
    if tc1 != 0:
        return None
    return int(now_s * 1e9), int(ts1)
