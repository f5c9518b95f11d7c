"""The offboard state machine (pure: it is handed the time and what the links report, and
answers what to command and what to ask PX4 for).

    link_down -> waiting_target <-> ready --start--> starting --PX4 in offboard--> intercept
    intercept --abort | target lost | pass done--> braking --slow--> finished (PX4 hold)
    (target lost: the loop's coast, re-acquisition and search are over; pass done: the
    target filled ``done_size_frac`` of the view, then the track went stale)
    any state with the flight controller's link gone --> link_lost (nothing is commanded)

Offboard is requested only on the operator's start command (or ``auto_start`` in SITL), and
only after setpoints have streamed for ``STREAM_BEFORE_OFFBOARD_S``, as PX4 requires.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

from ..enums import RuntimeState
from ..track_loss import PASS_DONE, intercept_over

STREAM_BEFORE_OFFBOARD_S = 0.3
START_TIMEOUT_S = 3.0  # PX4 has not entered offboard by then: give up, back to ready
LINK_TIMEOUT_S = 0.5  # the flight controller silent this long: link lost
OFFBOARD_EXIT_GRACE_S = 0.3  # PX4 out of offboard for this long while intercepting: finished
REQUEST_EVERY_S = 0.5  # repeat arm / mode requests this often until PX4 complies


State = RuntimeState  # declared in onboard.enums


class Output(enum.Enum):
    NONE = "none"  # send nothing to the flight controller
    LOOP = "loop"  # the interception loop's command
    BRAKE = "brake"  # the loop's brake-and-hold command


@dataclass(frozen=True)
class Inputs:
    now_s: float
    fc_silence_s: float | None  # since the flight controller's last message; None: no heartbeat yet
    armed: bool
    offboard: bool  # PX4 reports offboard mode
    tracking: bool  # the loop has a live target estimate
    target_lost: bool  # the loop gave the target up (its search is over): the failsafe
    target_size_frac: float  # last detection's width / image width
    speed_m_s: float
    target_stale: bool = False  # the loop coasts, re-acquires or searches (no live track)


@dataclass
class Decision:
    output: Output
    request_arm: bool = False
    request_offboard: bool = False
    request_hold: bool = False
    request_streams: bool = False  # ask PX4 for the state messages at the loop's rates
    events: list[tuple[str, str]] = field(default_factory=list)  # (severity, text)


class OffboardStateMachine:
    """The offboard state machine: :meth:`step` once per tick with that tick's inputs."""

    def __init__(
        self, done_size_frac: float = 0.2, hold_speed_m_s: float = 0.3, auto_start: bool = False
    ) -> None:
        self.state = State.LINK_DOWN
        self.reason = ""
        self.done_size_frac = done_size_frac
        self.hold_speed_m_s = hold_speed_m_s
        self.auto_start = auto_start
        self._entered_s = 0.0
        self._last_request_s = -1e9
        self._offboard_gone_s: float | None = None
        self._start_pending = False
        self._abort_pending = False
        self._tracking = False
        self.max_size_frac = 0.0

    # ------------------------------------------------------------------ operator
    def command_start(self) -> tuple[bool, str]:
        """The operator's start: accepted only with a target in view and the link up."""
        if self.state is State.READY or (self.state is State.FINISHED and self._tracking):
            self._start_pending = True
            return True, "start accepted"
        if self.state in (State.STARTING, State.INTERCEPT):
            return True, "already started"
        if self.state in (State.WAITING_TARGET, State.FINISHED):
            return False, "start refused: no target in view"
        if self.state in (State.LINK_DOWN, State.LINK_LOST):
            return False, "start refused: no flight-controller link"
        return False, f"start refused: {self.state.value}"

    def command_abort(self) -> tuple[bool, str]:
        if self.state in (State.STARTING, State.INTERCEPT):
            self._abort_pending = True
            return True, "abort accepted"
        return True, f"abort: nothing flying ({self.state.value})"

    @property
    def flying(self) -> bool:
        return self.state in (State.STARTING, State.INTERCEPT, State.BRAKING)

    # ------------------------------------------------------------------ the step
    def _go(self, state: State, now: float, d: Decision, severity: str, text: str) -> None:
        self.state = state
        self._entered_s = now
        self._last_request_s = -1e9
        d.events.append((severity, text))

    def step(self, i: Inputs) -> Decision:
        now = i.now_s
        d = Decision(Output.NONE)
        link_ok = i.fc_silence_s is not None and i.fc_silence_s <= LINK_TIMEOUT_S
        s = self.state
        self._tracking = i.tracking
        if i.tracking:
            self.max_size_frac = max(self.max_size_frac, i.target_size_frac)
        if not link_ok:
            if s not in (State.LINK_DOWN, State.LINK_LOST):
                was_flying = self.flying
                self.reason = "flight-controller link lost"
                self._go(
                    State.LINK_LOST,
                    now,
                    d,
                    "critical",
                    "FC link lost: commands stopped" + (" mid-sortie" if was_flying else ""),
                )
            self._start_pending = self._abort_pending = False
            return d
        if s in (State.LINK_DOWN, State.LINK_LOST):
            self._go(State.WAITING_TARGET, now, d, "info", "FC link up")
            d.request_streams = True
            s = self.state
        if s is State.FINISHED and self._start_pending:
            s = self.state = State.READY if i.tracking else State.WAITING_TARGET
        if s in (State.WAITING_TARGET, State.READY, State.FINISHED):
            if s is State.FINISHED:
                return d  # stays finished (the ground sees it) until the next start
            if i.tracking and s is State.WAITING_TARGET:
                self._go(State.READY, now, d, "info", "target in view: ready")
            elif not i.tracking and s is State.READY:
                self._go(State.WAITING_TARGET, now, d, "warning", "target out of view")
            if self.state is State.READY and (self._start_pending or self.auto_start):
                self._start_pending = False
                self.max_size_frac = i.target_size_frac
                self._go(State.STARTING, now, d, "info", "starting: streaming setpoints")
            else:
                return d
        s = self.state
        if self._abort_pending:
            self._abort_pending = False
            if s in (State.STARTING, State.INTERCEPT):
                self.reason = "aborted by the operator"
                self._go(State.BRAKING, now, d, "warning", "abort: braking and holding")
                s = self.state
        if s is State.STARTING:
            d.output = Output.LOOP
            if i.offboard and i.armed:
                self._offboard_gone_s = None
                self._go(State.INTERCEPT, now, d, "info", "offboard: intercepting")
            elif now - self._entered_s > START_TIMEOUT_S:
                self.reason = "PX4 did not enter offboard"
                self._go(
                    State.READY if i.tracking else State.WAITING_TARGET,
                    now,
                    d,
                    "error",
                    "start failed: PX4 did not enter offboard",
                )
                d.output = Output.NONE
            elif now - self._entered_s >= STREAM_BEFORE_OFFBOARD_S and (
                now - self._last_request_s >= REQUEST_EVERY_S
            ):
                self._last_request_s = now
                d.request_arm = not i.armed
                d.request_offboard = i.armed and not i.offboard
            return d
        if s is State.INTERCEPT:
            d.output = Output.LOOP
            if not i.offboard:
                if self._offboard_gone_s is None:
                    self._offboard_gone_s = now
                if now - self._offboard_gone_s >= OFFBOARD_EXIT_GRACE_S:
                    self.reason = "PX4 left offboard"
                    self._go(State.FINISHED, now, d, "warning", "PX4 left offboard: stopped")
                    d.output = Output.NONE
                return d
            self._offboard_gone_s = None
            over = intercept_over(
                self.max_size_frac, self.done_size_frac, i.target_stale, i.target_lost
            )
            if over is not None:
                done = over == PASS_DONE
                self.reason = over
                self._go(
                    State.BRAKING,
                    now,
                    d,
                    "info" if done else "warning",
                    ("pass done" if done else "target lost") + ": braking and holding",
                )
                d.output = Output.BRAKE
            return d
        if s is State.BRAKING:
            d.output = Output.BRAKE
            if not i.offboard:
                self._go(State.FINISHED, now, d, "info", f"finished ({self.reason}): PX4 holds")
                d.output = Output.NONE
            elif i.speed_m_s <= self.hold_speed_m_s and (
                now - self._last_request_s >= REQUEST_EVERY_S
            ):
                self._last_request_s = now
                d.request_hold = True
            return d
        return d
