"""Runs ``groundstation sitl`` and ``onboard run`` as separate processes on loopback, with
this test process as the ground (or a real ground station), for the SITL tests."""

from __future__ import annotations

import contextlib
import json
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

from onboard.enums import RuntimeState
from onboard.link import telemetry as tm
from onboard.link.px4 import CMD_ABORT, CMD_START, MavLink, mavlink, message_text


def free_port(kind=socket.SOCK_DGRAM) -> int:
    return free_ports(kind)[0]


def free_ports(*kinds) -> list[int]:
    """Distinct free loopback ports, one per socket kind: all held open while picked, so the
    kernel cannot hand out the same number twice."""
    socks = [socket.socket(socket.AF_INET, kind) for kind in kinds]
    try:
        for s in socks:
            s.bind(("127.0.0.1", 0))
        ports = [s.getsockname()[1] for s in socks]
    finally:
        for s in socks:
            s.close()
    if len(set(ports)) < len(ports):  # a UDP and a TCP port may share a number: pick again
        return free_ports(*kinds)
    return ports


STARTUP_TIMEOUT_S = 120.0
# the vehicle's side (the SITL standing in for PX4 on its own processor, and the onboard
# runtime's control thread, as flown with --realtime) under SCHED_FIFO at this priority where
# the system allows it, so other programs on a loaded machine do not starve it; 1, the lowest:
# under any real-time benchmark. 0: both at normal priority.
VEHICLE_FIFO_PRIORITY = int(os.environ.get("PEREGRINE_RIG_FIFO", "1"))


def fifo_allowed(priority: int) -> bool:
    """May this process's children run under SCHED_FIFO at ``priority``?"""
    if priority <= 0 or not hasattr(os, "sched_setscheduler"):
        return False
    import resource

    return os.geteuid() == 0 or resource.getrlimit(resource.RLIMIT_RTPRIO)[0] >= priority


def _fifo(priority: int):
    """A ``preexec_fn`` putting the child (all its threads) under SCHED_FIFO (refused after
    all, a container without CAP_SYS_NICE: it runs at normal priority)."""

    def set_policy() -> None:
        with contextlib.suppress(OSError):
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))

    return set_policy


class Rig:
    def __init__(
        self,
        tmp: Path,
        scenario: str = "cv-top-to-bottom",
        sitl_args: tuple[str, ...] = (),
        onboard_args: tuple[str, ...] = (),
        sitl_listens: bool = True,
        onboard_gcs_listens: bool = False,
        ground: bool = True,
    ) -> None:
        self.tmp = tmp
        self.fc_port, self.gcs_port, self.cam_port = free_ports(
            socket.SOCK_DGRAM, socket.SOCK_DGRAM, socket.SOCK_STREAM
        )
        fc = f"udp{'in' if sitl_listens else 'out'}:127.0.0.1:{self.fc_port}"
        onb_fc = f"udp{'out' if sitl_listens else 'in'}:127.0.0.1:{self.fc_port}"
        onb_gcs = f"udp{'in' if onboard_gcs_listens else 'out'}:127.0.0.1:{self.gcs_port}"
        env = dict(os.environ, PYTHONUNBUFFERED="1")
        py = sys.executable
        prio = VEHICLE_FIFO_PRIORITY
        self.realtime = fifo_allowed(prio)
        fifo = _fifo(prio) if self.realtime else None
        realtime = ("--realtime", str(prio)) if self.realtime else ()
        self.sitl_out = tmp / "sitl.log"
        self.onboard_out = tmp / "onboard.log"
        self.stats = tmp / "stats.json"
        self.params = tmp / "params.toml"
        self.sitl = subprocess.Popen(
            [py, "-m", "groundstation", "sitl", scenario, "--mavlink", fc,
             "--camera-port", str(self.cam_port), *sitl_args],
            stdout=self.sitl_out.open("w"), stderr=subprocess.STDOUT, env=env, cwd=tmp,
            preexec_fn=fifo,
        )  # fmt: skip
        self.ground = None
        if ground:
            ground_url = f"udp{'out' if onboard_gcs_listens else 'in'}:127.0.0.1:{self.gcs_port}"
            self.ground = MavLink(ground_url, 255, 190)
        self.onboard = subprocess.Popen(
            [py, "-m", "onboard", "run", "--mavlink", onb_fc,
             "--camera", f"sitl://127.0.0.1:{self.cam_port}", "--gcs", onb_gcs,
             "--params", str(self.params), "--stats", str(self.stats), *realtime, *onboard_args],
            stdout=self.onboard_out.open("w"), stderr=subprocess.STDOUT, env=env, cwd=tmp,
        )  # fmt: skip
        self.texts: list[tuple[float, str]] = []  # (receipt time, STATUSTEXT)
        self.telemetry: list[dict] = []
        self.acks: list[tuple[int, int]] = []
        self.params_seen: dict[str, float] = {}
        self._last_hb = -1e9
        self._up = False

    # -------------------------------------------------------------- conditions
    def wait_up(self, timeout_s: float = STARTUP_TIMEOUT_S) -> None:
        """Both processes started and listening: the SITL printed its camera and MAVLink
        addresses and the onboard runtime said it is up, in their own logs (which no link can
        lose). Starting two Python processes is what a loaded machine slows most, and is not
        what the tests test: the waits after this one count from here."""
        end = time.monotonic() + timeout_s
        while not self._up:
            self._up = (
                "sitl: camera " in self.sitl_out.read_text()
                and "onboard up:" in self.onboard_out.read_text()
            )
            if self._up:
                return
            if time.monotonic() >= end:
                raise AssertionError(f"processes not up within {timeout_s} s\n{self.logs()}")
            if self.ground is not None:
                self.pump(0.05)
            else:
                time.sleep(0.05)
            self.check_alive()

    def wait_state(self, state: RuntimeState, timeout_s: float = 15.0) -> dict:
        """The first telemetry sample in ``state``, counted from both processes being up. The
        runtime streams its state at 50 Hz, so this does not miss what a one-shot STATUSTEXT
        can: with the onboard runtime listening on the ground port, what it says before the
        ground's first heartbeat reaches it (its peer's address unknown) goes nowhere."""
        self.wait_up()
        code = tm.STATE_CODES.index(state.value)
        end = time.monotonic() + timeout_s
        n = 0
        while time.monotonic() < end:
            for t in self.telemetry[n:]:
                if t["state"] == code:
                    return t
            n = len(self.telemetry)
            self.pump(0.05)
            self.check_alive()
        raise AssertionError(
            f"no telemetry in state {state.value!r} within {timeout_s} s; got {self.texts}\n"
            f"{self.logs()}"
        )

    def wait_ready(self, timeout_s: float = 15.0) -> dict:
        """The target in view and the runtime ready to start (the ground hears it)."""
        return self.wait_state(RuntimeState.READY, timeout_s)

    # -------------------------------------------------------------- the ground
    def pump(self, seconds: float = 0.0) -> None:
        end = time.monotonic() + seconds
        while True:
            if time.monotonic() - self._last_hb > 0.5:  # a ground station's heartbeat
                self._last_hb = time.monotonic()
                self.ground.heartbeat(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            for m in self.ground.poll():
                k = m.get_type()
                if k == "STATUSTEXT":
                    self.texts.append((time.monotonic(), message_text(m)))
                elif k == "DEBUG_FLOAT_ARRAY" and m.array_id == tm.ARRAY_ID:
                    self.telemetry.append(tm.unpack(m.data))
                elif k == "COMMAND_ACK":
                    self.acks.append((m.command, m.result))
                elif k == "PARAM_VALUE":
                    name = m.param_id if isinstance(m.param_id, str) else m.param_id.decode()
                    self.params_seen[name.rstrip("\x00")] = m.param_value
            if time.monotonic() >= end:
                return
            time.sleep(0.005)

    def wait_text(self, needle: str, timeout_s: float = 15.0, after: int = 0) -> float:
        """Receipt time of the first STATUSTEXT containing ``needle`` (from index ``after``),
        counted from both processes being up."""
        self.wait_up()
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            for t, text in self.texts[after:]:
                if needle in text:
                    return t
            self.pump(0.05)
            self.check_alive()
        raise AssertionError(f"no {needle!r} within {timeout_s} s; got {self.texts}\n{self.logs()}")

    def command(self, command: int, timeout_s: float = 1.0, sends: int = 3) -> int:
        """As a ground station sends a command: again, its confirmation counting up, when no
        COMMAND_ACK came back within ``timeout_s`` (the command protocol)."""
        n = len(self.acks)
        for confirmation in range(sends):
            self.ground.send(
                self.ground.mav.command_long_encode(
                    1, 191, command, confirmation, 0, 0, 0, 0, 0, 0, 0
                )
            )
            end = time.monotonic() + timeout_s
            while time.monotonic() < end:
                self.pump(0.02)
                for cmd, result in self.acks[n:]:
                    if cmd == command:
                        return result
        raise AssertionError(f"no COMMAND_ACK for {command} after {sends} sends\n{self.logs()}")

    def start(self) -> int:
        return self.command(CMD_START)

    def abort(self) -> int:
        return self.command(CMD_ABORT)

    def param_set(self, name: str, value: float, timeout_s: float = 6.0) -> float:
        """The value the vehicle answers; PARAM_SET is sent again each second without one,
        as ground stations do (setting a value twice is harmless)."""
        self.params_seen.pop(name, None)
        end = time.monotonic() + timeout_s
        resend = 0.0
        while time.monotonic() < end:
            if time.monotonic() >= resend:
                resend = time.monotonic() + 1.0
                msg = self.ground.mav.param_set_encode(1, 191, name.encode(), value, 9)
                self.ground.send(msg)
            self.pump(0.02)
            if name in self.params_seen:
                return self.params_seen[name]
        raise AssertionError(f"no PARAM_VALUE for {name}")

    # -------------------------------------------------------------- the processes
    def check_alive(self) -> None:
        for name, p in (("sitl", self.sitl), ("onboard", self.onboard)):
            if p.poll() is not None and p is not getattr(self, "_killed", None):
                raise AssertionError(f"{name} exited with {p.returncode}\n{self.logs()}")

    def sitl_result(self, timeout_s: float = 20.0) -> dict:
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            for line in self.sitl_out.read_text().splitlines():
                if line.startswith("SITL_RESULT "):
                    return json.loads(line.removeprefix("SITL_RESULT "))
            if self.ground is not None:
                self.pump(0.1)
            else:
                time.sleep(0.1)
            self.check_alive()
        raise AssertionError(f"no SITL result\n{self.logs()}")

    def logs(self) -> str:
        return (
            f"--- sitl\n{self.sitl_out.read_text()[-3000:]}\n"
            f"--- onboard\n{self.onboard_out.read_text()[-3000:]}"
        )

    def close(self) -> dict | None:
        for p in (self.onboard, self.sitl):
            if p.poll() is None:
                p.terminate()
        for p in (self.onboard, self.sitl):
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:
                p.kill()
        if self.ground is not None:
            self.ground.close()
        return json.loads(self.stats.read_text()) if self.stats.exists() else None
