"""The project's enumerations, each declared once here. Everything else derives from them:
the MAVLink codes (a member's code is its index in declaration order, see :func:`codes`),
the guidance-law table, the CLI choices, the campaign laws and the dashboard's option lists
(served by ``GET /api/meta``). ``tests/test_enums.py`` fails if a second list appears."""

from __future__ import annotations

import enum


class GuidanceLaw(str, enum.Enum):
    """Guidance laws (DESIGN.md §5): the proposed one first (MAVLink ``LAW`` code order)."""

    PNG = "png"  # IBVS fused with proportional navigation (the paper's law)
    PG = "pg"  # pursuit guidance
    IBVS = "ibvs"  # image-based visual servoing
    APN = "apn"  # augmented PN: the proposed law plus the target's acceleration (docs/agility.md)


# the law flown wherever none is named (simulator, dashboard, tuning, the vehicle's LAW parameter)
DEFAULT_LAW: GuidanceLaw = GuidanceLaw.PNG

# the paper's comparison: what a campaign flies unless told which laws
PAPER_LAWS: tuple[GuidanceLaw, ...] = (GuidanceLaw.PNG, GuidanceLaw.PG, GuidanceLaw.IBVS)


class LoopMode(enum.Enum):
    """What the interception loop is doing at a control tick."""

    WAITING = "waiting"  # no target estimate yet: hold position
    TRACKING = "tracking"  # guidance law active
    LOST = "lost"  # estimate lost and the search over: brake and hold (the failsafe)
    BRAKE = "brake"  # told to brake and hold (operator abort), estimate still running
    # appended (the MAVLink code is the index): track loss and re-acquisition, see
    # onboard/control/reacquire.py
    COAST = "coast"  # no fresh detection: guidance law on the DKF's prediction
    REACQUIRE = "reacquire"  # prediction too old: yaw toward it, slow down, wait for a detection
    SEARCH = "search"  # no usable prediction: yaw scan at hover, or fly the cue, time-bounded


class RuntimeState(enum.Enum):
    """The onboard component's offboard state machine (onboard/runtime/state_machine.py)."""

    LINK_DOWN = "link_down"
    WAITING_TARGET = "waiting_target"
    READY = "ready"
    STARTING = "starting"
    INTERCEPT = "intercept"
    BRAKING = "braking"
    FINISHED = "finished"
    LINK_LOST = "link_lost"


class Outcome(str, enum.Enum):
    """How a simulated sortie ended."""

    HIT = "HIT"
    MISS = "MISS"
    TIMEOUT = "TIMEOUT"
    TARGET_LOST = "TARGET_LOST"
    CRASHED = "CRASHED"
    DIVERGED = "DIVERGED"


def codes(enumeration: type[enum.Enum]) -> tuple[str, ...]:
    """The members' values in declaration order: index = MAVLink code."""
    return tuple(m.value for m in enumeration)


def describe_codes(enumeration: type[enum.Enum]) -> str:
    """``"0 png, 1 pg, 2 ibvs"``: the code table in words (parameter and field help)."""
    return ", ".join(f"{i} {v}" for i, v in enumerate(codes(enumeration)))


def meta() -> dict[str, list[str]]:
    """Every enumeration the operator chooses from or reads, by name (``GET /api/meta``)."""
    return {
        "laws": list(codes(GuidanceLaw)),
        "loop_modes": list(codes(LoopMode)),
        "runtime_states": list(codes(RuntimeState)),
        "outcomes": list(codes(Outcome)),
    }
