"""``groundstation sitl`` as a PX4 user's tools see it: global position around a configurable
home, landed state, sensor health and battery, autopilot parameters (PX4's byte-wise INT32),
takeoff / RTL / land from the ground, TIMESYNC; and, where MAVSDK-Python is installed, MAVSDK's
own connect -> position -> in_air -> arm -> takeoff."""

from __future__ import annotations

import asyncio
import math
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
import tomli_w

from groundstation.scenario import shipped_scenarios
from groundstation.sitl.autopilot import (
    AUTOPILOT_PARAMS,
    PARAM_INT32,
    SENSORS_HEALTHY,
    AutopilotParams,
    Battery,
    Home,
    decode_value,
    encode_value,
)
from onboard.link.px4 import MavLink, mavlink, param_id_str
from onboard.runtime.px4_params import check

from .sitl_rig import STARTUP_TIMEOUT_S, Rig, free_ports

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

HOME = Home(52.0, 4.0, 10.0)
START_E_M = 8.0  # the interceptor starts 8 m east of home


# ---------------------------------------------------------------------- pure parts
def test_global_position_battery_and_parameters_units():
    lat, lon, alt = HOME.to_global((100.0, 200.0, 5.0))
    assert lat == pytest.approx(52.0 + math.degrees(200.0 / 6_378_137.0), abs=1e-9)
    assert (lon - 4.0) * math.radians(1) * 6_378_137.0 * math.cos(math.radians(52.0)) == (
        pytest.approx(100.0, rel=1e-9)
    )
    assert alt == 15.0
    with pytest.raises(ValueError):
        Home(95.0, 0.0, 0.0)
    b = Battery(cells=4, capacity_mah=5000.0, hover_current_a=18.0, idle_current_a=0.8)
    assert b.voltage_v == pytest.approx(16.8) and b.remaining == 1.0
    for _ in range(600):  # one minute hovering
        b.step(0.1, armed=True, thrust_over_hover=1.0)
    assert b.consumed_mah == pytest.approx(18.8 * 60 / 3.6, rel=1e-9)  # 313 mAh
    assert b.remaining == pytest.approx(1.0 - 313.33 / 5000.0, abs=1e-4)
    assert b.voltage_v == pytest.approx(4 * (3.5 + 0.7 * b.remaining) - 18.8 * 0.02)
    b.step(1.0, armed=False, thrust_over_hover=1.0)
    assert b.current_a == 0.0
    p = AutopilotParams()
    assert p["MPC_XY_VEL_MAX"] == 12.0 and p["COM_OF_LOSS_T"] == 1.0
    assert not p.set("MPC_XY_VEL_MAX", 99.0) and not p.set("COM_OF_LOSS_T", math.nan)
    assert not p.set("BAT1_N_CELLS", 3.5) and p.set("BAT1_N_CELLS", 6)
    for v in (0, 4, 10016, -1):
        assert decode_value(encode_value(v, PARAM_INT32), PARAM_INT32) == v


def test_bad_sitl_options_are_refused_with_a_clear_error(capsys):
    from groundstation.cli import main

    for argv, needle in (
        (["--home", "95,0,0"], "not a latitude/longitude"),
        (["--home", "52,4"], "--home 52,4"),
        (["--offboard-loss", "100"], "expected 0 to 60 s"),
        (["--set", "estimate.lag_s=-1"], "estimate.lag_s"),
        (["--set", "camera.no_such_key=1"], "no_such_key"),
    ):
        assert main(["sitl", "--camera-port", "0", "--duration", "0.1", *argv]) == 2
        assert needle in capsys.readouterr().err


# ---------------------------------------------------------------------- the SITL process
class Px4Client:
    """A ground station's view of the SITL: the latest message of each type."""

    def __init__(self, tmp: Path, *args: str) -> None:
        self.port, cam = free_ports(socket.SOCK_DGRAM, socket.SOCK_STREAM)
        doc = tomllib.loads(
            next(p for p in shipped_scenarios() if p.stem == "cv-top-to-bottom").read_text()
        )
        doc["interceptor"]["position_m"] = [START_E_M, 0.0, 10.0]
        scenario = tmp / "east.toml"
        scenario.write_text(tomli_w.dumps(doc))
        self.out = tmp / "sitl.log"
        home = f"{HOME.lat_deg},{HOME.lon_deg},{HOME.alt_m}"
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "groundstation", "sitl", str(scenario), "--mavlink",
             f"udpout:127.0.0.1:{self.port}", "--camera-port", str(cam), "--home", home, *args],
            stdout=self.out.open("w"), stderr=subprocess.STDOUT,
            env=dict(os.environ, PYTHONUNBUFFERED="1"),
        )  # fmt: skip
        self.link = MavLink(f"udpin:127.0.0.1:{self.port}", 255, 190)
        self.last: dict[str, object] = {}
        self.params: dict[str, tuple[float, int]] = {}
        self.acks: list[tuple[int, int]] = []
        self.texts: list[str] = []
        self.timesync: list[tuple[float, object]] = []

    def pump(self, seconds: float = 0.05) -> None:
        end = time.monotonic() + seconds
        while True:
            for m in self.link.poll():
                k = m.get_type()
                if m.get_srcSystem() != 1:
                    continue  # the cooperative target (system 2)
                self.last[k] = m
                if k == "PARAM_VALUE":
                    self.params[param_id_str(m.param_id)] = (m.param_value, m.param_type)
                elif k == "COMMAND_ACK":
                    self.acks.append((m.command, m.result))
                elif k == "STATUSTEXT":
                    self.texts.append(m.text)
                elif k == "TIMESYNC":
                    self.timesync.append((time.monotonic(), m))
            if time.monotonic() >= end:
                return
            time.sleep(0.005)

    def wait_up(self) -> None:
        """The process started and listening (its log says so): a loaded machine is slowest
        at starting Python, which is not what is tested; the waits after this count from here."""
        end = time.monotonic() + STARTUP_TIMEOUT_S
        while "sitl: camera " not in self.out.read_text():
            assert self.proc.poll() is None, self.out.read_text()
            assert time.monotonic() < end, f"SITL not up\n{self.out.read_text()}"
            time.sleep(0.05)

    def wait(self, pred, timeout_s: float, what: str):
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            self.pump()
            if pred():
                return
            assert self.proc.poll() is None, self.out.read_text()
        raise AssertionError(f"no {what} in {timeout_s} s; {self.texts}\n{self.out.read_text()}")

    def command(self, cmd: int, *params: float) -> int:
        n = len(self.acks)
        p = list(params) + [0.0] * (7 - len(params))
        self.link.send(self.link.mav.command_long_encode(1, 1, cmd, 0, *p))
        self.wait(lambda: any(c == cmd for c, _ in self.acks[n:]), 3.0, f"ACK of {cmd}")
        return next(r for c, r in self.acks[n:] if c == cmd)

    def param_set(self, name: str, value: float, kind: int = mavlink.MAV_PARAM_TYPE_REAL32):
        self.params.pop(name, None)
        wire = encode_value(value, PARAM_INT32) if kind == PARAM_INT32 else value
        self.link.send(self.link.mav.param_set_encode(1, 1, name.encode(), wire, kind))
        self.wait(lambda: name in self.params, 3.0, f"PARAM_VALUE {name}")
        return decode_value(*self.params[name])

    def close(self) -> None:
        self.proc.terminate()
        self.proc.wait(10)
        self.link.close()


@pytest.fixture
def px4(tmp_path):
    # ideal sensors: the position conversions below are checked to the centimetre (the
    # estimate model's errors are tested in test_sitl_models.py)
    client = Px4Client(tmp_path, "--on-ground", "--set", "estimate.enabled=false")
    try:
        client.wait_up()
        client.wait(lambda: "GLOBAL_POSITION_INT" in client.last, 15.0, "first position")
        yield client
    finally:
        client.close()


def test_on_the_ground_a_ground_station_sees_position_health_battery_and_home(px4):
    px4.wait(lambda: {"SYS_STATUS", "BATTERY_STATUS", "EXTENDED_SYS_STATE", "HOME_POSITION",
                      "HEARTBEAT"} <= set(px4.last), 5.0, "status messages")  # fmt: skip
    g = px4.last["GLOBAL_POSITION_INT"]
    lat, lon, _ = HOME.to_global((START_E_M, 0.0, 0.0))
    assert abs(g.lat - lat * 1e7) <= 1 and abs(g.lon - lon * 1e7) <= 1  # ~1 cm
    assert g.alt == 10_000 and g.relative_alt == 0 and abs(g.hdg - 0) <= 1  # nose north
    h = px4.last["HOME_POSITION"]
    assert (h.latitude, h.longitude, h.altitude) == (520_000_000, 40_000_000, 10_000)
    assert px4.last["EXTENDED_SYS_STATE"].landed_state == mavlink.MAV_LANDED_STATE_ON_GROUND
    s = px4.last["SYS_STATUS"]
    assert s.onboard_control_sensors_health == s.onboard_control_sensors_present == SENSORS_HEALTHY
    assert s.voltage_battery == 16_800 and s.battery_remaining == 100 and s.current_battery == 0
    b = px4.last["BATTERY_STATUS"]
    assert list(b.voltages[:4]) == [4200] * 4 and b.battery_remaining == 100
    hb = px4.last["HEARTBEAT"]
    assert not hb.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED
    assert (
        hb.system_status == mavlink.MAV_STATE_STANDBY and hb.autopilot == mavlink.MAV_AUTOPILOT_PX4
    )
    # a message on request
    n = len(px4.acks)
    assert px4.command(mavlink.MAV_CMD_REQUEST_MESSAGE, 148) == mavlink.MAV_RESULT_ACCEPTED
    px4.wait(lambda: "AUTOPILOT_VERSION" in px4.last, 3.0, "AUTOPILOT_VERSION")
    caps = px4.last["AUTOPILOT_VERSION"].capabilities
    assert caps & mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE and len(px4.acks) > n


def test_autopilot_parameters_over_the_parameter_protocol(px4):
    px4.link.send(px4.link.mav.param_request_list_encode(1, 1))
    px4.wait(lambda: len(px4.params) == len(AUTOPILOT_PARAMS), 5.0, "every parameter")
    values = {k: decode_value(*v) for k, v in px4.params.items()}
    assert values["MPC_XY_VEL_MAX"] == 12.0 and values["COM_OF_LOSS_T"] == 1.0
    assert values["BAT1_N_CELLS"] == 4 and px4.params["BAT1_N_CELLS"][1] == PARAM_INT32
    assert values["MPC_THR_HOVER"] == pytest.approx(1 / 3, abs=1e-6)  # from thrust_to_weight 3
    assert px4.param_set("COM_OF_LOSS_T", 0.5) == 0.5
    assert px4.param_set("MPC_XY_VEL_MAX", 500.0) == 12.0  # refused: the old value comes back
    assert px4.param_set("BAT1_N_CELLS", 6, PARAM_INT32) == 6
    assert px4.param_set("BAT1_N_CELLS", 6.0) == 6  # a REAL32 for an INT32: refused
    px4.link.send(px4.link.mav.param_request_read_encode(1, 1, b"COM_OF_LOSS_T", -1))
    px4.params.pop("COM_OF_LOSS_T")
    px4.wait(lambda: "COM_OF_LOSS_T" in px4.params, 3.0, "read by name")
    assert px4.params["COM_OF_LOSS_T"][0] == 0.5


def test_arm_takeoff_rtl_and_land_from_the_ground(px4):
    for name, value in (("MIS_TAKEOFF_ALT", 3.0), ("RTL_RETURN_ALT", 5.0),
                        ("MPC_LAND_SPEED", 2.0), ("COM_DISARM_LAND", 0.5)):  # fmt: skip
        assert px4.param_set(name, value) == value
    takeoff = mavlink.MAV_CMD_NAV_TAKEOFF
    assert px4.command(takeoff, 0, 0, 0, math.nan, 0, 0, math.nan) == mavlink.MAV_RESULT_DENIED
    assert px4.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == mavlink.MAV_RESULT_ACCEPTED
    assert px4.command(takeoff, 0, 0, 0, math.nan, 0, 0, math.nan) == mavlink.MAV_RESULT_ACCEPTED
    state = lambda: px4.last["EXTENDED_SYS_STATE"].landed_state  # noqa: E731
    px4.wait(lambda: state() == mavlink.MAV_LANDED_STATE_TAKEOFF, 2.0, "TAKEOFF state")
    px4.wait(lambda: state() == mavlink.MAV_LANDED_STATE_IN_AIR, 10.0, "IN_AIR")
    px4.pump(1.0)
    g = px4.last["GLOBAL_POSITION_INT"]
    assert abs(g.relative_alt - 3000) < 300 and abs(g.alt - 13_000) < 300  # 3 m +- 0.3
    assert px4.last["SYS_STATUS"].current_battery > 1000  # > 10 A hovering
    assert px4.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0) == mavlink.MAV_RESULT_DENIED
    assert px4.command(mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH) == mavlink.MAV_RESULT_ACCEPTED
    px4.wait(lambda: px4.last["GLOBAL_POSITION_INT"].relative_alt > 4700, 6.0, "RTL climb")
    px4.wait(lambda: state() == mavlink.MAV_LANDED_STATE_LANDING, 10.0, "RTL landing")
    px4.wait(lambda: state() == mavlink.MAV_LANDED_STATE_ON_GROUND, 10.0, "touchdown")
    g = px4.last["GLOBAL_POSITION_INT"]
    east_m = (
        (g.lon / 1e7 - HOME.lon_deg)
        * math.radians(1)
        * 6_378_137.0
        * math.cos(math.radians(HOME.lat_deg))
    )
    assert abs(east_m) < 0.5 and g.relative_alt == 0  # home, from 8 m east
    px4.wait(lambda: not px4.last["HEARTBEAT"].base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED,
             3.0, "disarm after landing")  # fmt: skip
    assert px4.last["BATTERY_STATUS"].current_consumed > 0
    assert px4.command(mavlink.MAV_CMD_NAV_LAND) == mavlink.MAV_RESULT_DENIED  # landed


def test_timesync_is_answered_on_the_vehicles_boot_clock(px4):
    before_ms = px4.last["GLOBAL_POSITION_INT"].time_boot_ms
    for i in range(20):
        px4.link.send(px4.link.mav.timesync_encode(0, 1000 + i))
        px4.pump(0.02)
    px4.pump(0.2)
    replies = [m for _, m in px4.timesync if m.tc1 != 0]
    assert sorted(m.ts1 for m in replies) == list(range(1000, 1020))
    after_ms = px4.last["GLOBAL_POSITION_INT"].time_boot_ms
    # the clock of time_boot_ms: each answer's time falls between the position reports
    # received before the first request and after the last answer (a busy machine delays the
    # reports, not the clock), give or take one report period
    for m in replies:
        assert before_ms - 100 <= m.tc1 / 1e6 <= after_ms + 300, (before_ms, m.tc1, after_ms)


def test_px4_parameter_checks():
    assert check("MPC_THR_HOVER", 0.36, 0.33, 12.0) is None
    assert check("MPC_THR_HOVER", 0.5, 0.33, 12.0) == (
        "warning",
        "PX4 MPC_THR_HOVER 0.50 != PRG_HOVER_THR 0.33",
    )
    assert check("COM_OF_LOSS_T", 0.8, 0.33, 12.0) is None
    assert check("COM_OF_LOSS_T", 3.0, 0.33, 12.0)[1] == "PX4 COM_OF_LOSS_T 3 s: advised 0.5-1 s"
    assert check("MPC_XY_VEL_MAX", 8.0, 0.33, 12.0)[0] == "info"
    assert check("COM_OF_LOSS_T", math.nan, 0.33, 12.0)[0] == "warning"
    assert all(len(check(*a)[1]) <= 50 for a in (("MPC_THR_HOVER", 0.95, 0.05, 1.0),))


def test_onboard_reads_px4_parameters_and_keeps_a_timesync_estimate(tmp_path):
    """``onboard run`` against the SITL: PX4's parameters it depends on are read at link-up
    and a mismatch is said (STATUSTEXT); it keeps a TIMESYNC estimate of the SITL's boot clock,
    and as both count from a zero on the same monotonic clock, the truth is known
    (``groundstation bench --sitl`` prints the same figure)."""
    from groundstation.bench.sitl import timesync_error

    (tmp_path / "params.toml").write_text("PRG_HOVER_THR = 0.5\n")
    rig = Rig(tmp_path, sitl_args=("--offboard-loss", "3"))
    try:
        rig.wait_text("PX4 MPC_THR_HOVER 0.33 != PRG_HOVER_THR 0.50", 20.0)
        rig.wait_text("PX4 COM_OF_LOSS_T 3 s: advised 0.5-1 s", 5.0)
        rig.wait_text("loop ready", 20.0)  # both processes up, the camera streaming
        rig.pump(4.0)
        rig.check_alive()
    finally:
        stats = rig.close()
    zero = next(
        float(line.split()[-2])
        for line in rig.sitl_out.read_text().splitlines()
        if line.startswith("sitl: boot clock zero at monotonic ")
    )
    assert stats["timesync_accepted"] >= 30  # 10 Hz for at least 4 s
    error_ms = timesync_error(stats, zero)
    # measured: -0.07 ms (quickest round trip 0.13 ms) on loopback; 1 ms leaves room for a
    # loaded CI machine and is still finer than the 5 ms control period
    print(
        f"TIMESYNC error {error_ms:.3f} ms, quickest round trip {stats['timesync_min_rtt_ms']} ms"
    )
    assert abs(error_ms) < 1.0, (error_ms, stats)


# ---------------------------------------------------------------------- MAVSDK
def test_mavsdk_connects_reads_position_and_in_air_arms_and_takes_off(tmp_path):
    """MAVSDK-Python with its bundled mavsdk_server (``pip install "mavsdk<4"``; optional)."""
    mavsdk = pytest.importorskip("mavsdk")
    if not hasattr(mavsdk.System, "connect"):
        pytest.skip("mavsdk>=4 (native binding) installed; this test drives the gRPC API")
    # ideal sensors: the position is checked to 1e-6 deg (the model's errors: test_sitl_models)
    client = Px4Client(tmp_path, "--on-ground", "--set", "estimate.enabled=false")
    client.link.close()  # MAVSDK takes the port
    try:
        figures = asyncio.run(_mavsdk_flight(mavsdk, client.port))
    finally:
        client.proc.terminate()
        client.proc.wait(10)
    print("MAVSDK figures", figures)
    lat, lon, _ = HOME.to_global((START_E_M, 0.0, 0.0))
    assert figures["lat"] == pytest.approx(lat, abs=1e-6)
    assert figures["lon"] == pytest.approx(lon, abs=1e-6)
    assert figures["in_air_before"] is False and figures["in_air_after"] is True
    assert figures["rel_alt_m"] == pytest.approx(2.5, abs=0.4)  # MIS_TAKEOFF_ALT


async def _mavsdk_flight(mavsdk, port: int) -> dict:
    drone = mavsdk.System(port=free_ports(socket.SOCK_STREAM)[0])  # mavsdk_server's gRPC
    t0 = time.monotonic()
    await drone.connect(system_address=f"udpin://127.0.0.1:{port}")
    figures: dict = {}

    async def first(gen, pred=lambda _x: True):
        async for x in gen:
            if pred(x):
                return x

    async def flight():
        await first(drone.core.connection_state(), lambda s: s.is_connected)
        figures["connect_s"] = time.monotonic() - t0
        pos = await first(drone.telemetry.position())
        figures["position_s"] = time.monotonic() - t0
        figures["lat"], figures["lon"] = pos.latitude_deg, pos.longitude_deg
        figures["in_air_before"] = await first(drone.telemetry.in_air())
        await first(drone.telemetry.health(), lambda h: h.is_global_position_ok)
        await drone.action.arm()
        await drone.action.takeoff()
        figures["in_air_after"] = await first(drone.telemetry.in_air(), lambda a: a)
        p = await first(drone.telemetry.position(), lambda p: p.relative_altitude_m > 2.3)
        figures["rel_alt_m"] = p.relative_altitude_m
        figures["takeoff_s"] = time.monotonic() - t0
        await asyncio.sleep(1.0)
        p = await first(drone.telemetry.position())
        figures["rel_alt_m"] = p.relative_altitude_m
        return figures

    try:
        return await asyncio.wait_for(flight(), 60.0)
    finally:
        drone._stop_mavsdk_server()
