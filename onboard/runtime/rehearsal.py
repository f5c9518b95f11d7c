"""The tick rehearsed just before its deadline (``onboard run --rehearse``, on by default).

On a machine whose caches a sleeping thread loses, a tick's time is mostly the refill of its
code and data, not its instructions: on the 2-core virtual machine here the loop's tick took
0.023 ms back to back and 0.16-0.31 ms after a 5 ms sleep (``groundstation bench --sitl``,
"this machine"). So the control thread wakes :data:`REHEARSE_LEAD_S` earlier than it otherwise
would and runs the tick's expensive part once on a copy: the shadow, a deep copy of the
interception loop, ticks the vehicle's current state, a copy of the offboard state machine
steps on its result, and the setpoint frame its command would make is packed and, on a UDP
link to PX4, sent from the same socket to one of the runtime's own on 127.0.0.1
(``MavLink.rehearse_send``: the system call and the kernel's UDP and IP layers warmed; README
"Session 21" under Measured), never to PX4. At the deadline the same code runs again on the
real loop with it in the caches.

Nothing of the rehearsal reaches the vehicle: the shadow is a deep copy (no mutable object
shared with the loop; the frozen gains, camera model and configurations are, a copy of one
being the object itself) and its result is dropped, so the commands flown are those flown
without it, to the bit (``tests/test_rehearsal.py``). The shadow is refreshed in the slack
after a tick (under the loop's lock) when the loop's mode differs from the shadow's, so the
rehearsal runs the branch the tick will run (tracking, coasting, searching), and at least
every :data:`SHADOW_MAX_AGE_TICKS` ticks. A rehearsal that raises drops its shadow (a new one is
taken after the next tick) and is counted; it never stops the loop.

The cost: a second tick's CPU per period (the process's CPU in ``bench --sitl`` shows it) and
a deep copy (about 0.5 ms) about once a second. Early ticks (a detection fused) are not
rehearsed: they start as soon as the fusion asks for them.
"""

from __future__ import annotations

import copy
from collections.abc import Callable

import numpy as np

from ..datatypes import ControlTelemetry, Detection, VehicleState
from ..link.px4 import ONBOARD_COMPONENT_ID, VEHICLE_SYSTEM_ID
from ..loop import InterceptionLoop
from .fc_side import SET_ATTITUDE_TARGET, setpoint_fields

REHEARSE_LEAD_S = 0.0003  # woken this much earlier than the spin before the deadline
SHADOW_MAX_AGE_TICKS = 200  # a shadow older than this many ticks is taken afresh
WARM_UP_TICKS = 40  # warm_up's ticks (0.2 s at 200 Hz), a detection fused every tenth


class Rehearsal:
    """The shadow loop and its counts. :meth:`needs_refresh` and :meth:`refresh` after a tick
    (the caller holds the loop's lock for the copy), :meth:`run` before the next one."""

    def __init__(self, max_age_ticks: int = SHADOW_MAX_AGE_TICKS) -> None:
        self.max_age_ticks = max_age_ticks
        self.shadow: InterceptionLoop | None = None
        self._age_ticks = 0
        self.runs = 0  # rehearsals run
        self.refreshes = 0  # shadows taken
        self.errors = 0  # rehearsals that raised (their shadow dropped)
        self.sends = 0  # rehearsals whose frame went to the runtime's own socket (``send``)
        # the runtime's wait for the loop's lock before a rehearsal (runner._rehearse)
        self.lock_declines = 0  # declined: another thread's batch kept it
        self.lock_waits = 0  # waited for it, then rehearsed
        self.lock_wait_max_s = 0.0

    def lock_waited(self, waited_s: float) -> None:
        """Count a wait of ``waited_s`` (s) for the loop's lock that ended with it taken."""
        self.lock_waits += 1
        self.lock_wait_max_s = max(self.lock_wait_max_s, waited_s)

    def needs_refresh(self, loop: InterceptionLoop) -> bool:
        """After a tick of ``loop``: whether the shadow is missing, of another mode than the
        loop's, or old."""
        self._age_ticks += 1
        sh = self.shadow
        return sh is None or sh.mode is not loop.mode or self._age_ticks > self.max_age_ticks

    def refresh(self, loop: InterceptionLoop) -> None:
        """Take a new shadow: a deep copy of ``loop`` (no mutable object shared with it)."""
        self.shadow = copy.deepcopy(loop)
        self._age_ticks = 0
        self.refreshes += 1

    def run(
        self,
        state: VehicleState,
        hold_s: float | None,
        then: Callable[[ControlTelemetry], object] | None = None,
        send: Callable[[bytes], bool] | None = None,
    ) -> bytes | None:
        """Tick the shadow at ``state`` (its command held ``hold_s``), hand its telemetry to
        ``then`` (the runtime steps a copy of its state machine on it: the rest of the tick's
        code), pack the setpoint frame of its command and hand it to ``send`` (the runtime's
        ``MavLink.rehearse_send``: to a socket of its own; True when sent, counted). Returns
        the frame, which must never reach PX4; None without a shadow, when the output guard
        refuses the command, or when the tick, ``then`` or ``send`` raised."""
        shadow = self.shadow
        if shadow is None:
            return None
        self.runs += 1
        try:
            tel = shadow.tick(state, False, hold_s)
            if then is not None:
                then(tel)
            cmd = tel.command
            fields = setpoint_fields(cmd.body_rates_flu_rad_s, cmd.thrust_normalised, state.time_s)
            if fields is None:
                return None
            frame = SET_ATTITUDE_TARGET.frame(0, VEHICLE_SYSTEM_ID, ONBOARD_COMPONENT_ID, fields)
            if send is not None and send(frame):
                self.sends += 1
            return frame
        except Exception:  # a copy's failure is no reason to stop flying: count it, drop it
            self.errors += 1
            self.shadow = None
            return None


def warm_up(loop: InterceptionLoop, period_s: float, ticks: int = WARM_UP_TICKS) -> int:
    """Before the vehicle's loop runs: tick ``loop``, a throwaway one, on made-up states
    ``period_s`` apart (level, 10 m up, 3 m/s north), with a detection at the image's centre
    fused every tenth tick and its setpoint frame packed, so that the code's first runs (the
    interpreter's, numba's and numpy's first calls) are paid here rather than by the real
    loop's first tick: about 0.8 ms of its 0.9-1.2 ms here, and a start-up tick, very likely
    that one, took 5.5 ms once on a busy host, an overrun (README "Session 21"). Returns the
    frames packed (those the output guard let through)."""
    cam = loop.camera
    packed = 0
    for k in range(ticks):
        t = k * period_s
        if k % 10 == 9:
            half = 0.02 * cam.width_px
            loop.on_detection(
                Detection(
                    t - 0.5 * period_s,
                    (cam.cu_px, cam.cv_px),
                    (cam.cu_px - half, cam.cv_px - half, 2 * half, 2 * half),
                    4 * half * half,
                )
            )
            loop.fuse_detections()
        state = VehicleState(
            t,
            np.array([0.0, 0.0, 10.0]),
            np.array([0.0, 3.0, 0.0]),
            np.array([1.0, 0.0, 0.0, 0.0]),
            np.zeros(3),
        )
        cmd = loop.tick(state, k == ticks - 1, period_s).command
        fields = setpoint_fields(cmd.body_rates_flu_rad_s, cmd.thrust_normalised, t)
        if fields is not None:
            SET_ATTITUDE_TARGET.frame(0, VEHICLE_SYSTEM_ID, ONBOARD_COMPONENT_ID, fields)
            packed += 1
    return packed
