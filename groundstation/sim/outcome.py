"""How a simulated sortie ends: its result, the closest approach inside one physics step, and
when the vehicle counts as recovered after the pass."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

from onboard.enums import Outcome

from .physics import OUTCOME_CRASHED, OUTCOME_DIVERGED, OUTCOME_HIT, OUTCOME_MISS, closest_approach

# the physics kernel's outcome codes
OUTCOME_OF_CODE = {
    OUTCOME_HIT: Outcome.HIT,
    OUTCOME_MISS: Outcome.MISS,
    OUTCOME_DIVERGED: Outcome.DIVERGED,
    OUTCOME_CRASHED: Outcome.CRASHED,
}

# After the pass the sortie goes on until the vehicle has recovered: slower than this, its
# thrust axis within this of vertical, at least this high, checked at each control tick; or
# until this long after the pass (not recovered: the outcome stands, ``recovered`` false).
RECOVERED_SPEED_M_S = 0.5
RECOVERED_TILT_DEG = 10.0
CLEARANCE_FLOOR_M = 0.3
RECOVERY_TIMEOUT_S = 6.0
_LEVEL_COS = math.cos(math.radians(RECOVERED_TILT_DEG))


def has_recovered(p_enu_m, v_enu_m_s, q_wxyz) -> bool:
    """Braked, level and above the clearance floor: position (m), velocity (m/s) and the
    body-to-world attitude quaternion (w, x, y, z) of the true state."""
    v0, v1, v2 = v_enu_m_s
    _w, x, y, _z = q_wxyz
    level = 1.0 - 2.0 * (x * x + y * y)  # body z's vertical component
    return (
        v0 * v0 + v1 * v1 + v2 * v2 <= RECOVERED_SPEED_M_S**2
        and level >= _LEVEL_COS
        and p_enu_m[2] >= CLEARANCE_FLOOR_M
    )


@dataclass(frozen=True)
class SortieResult:
    outcome: str
    miss_m: float
    intercept_time_s: float
    terminal_speed_m_s: float
    max_normal_accel_m_s2: float
    law: str
    seed: int
    scenario: str
    camera: str
    sim_time_s: float
    hit_radius_m: float
    detections_fused: int
    detections_rejected: int
    guard_trips: int
    profile: str = ""  # the state-estimate error profile flown ("ideal": ideal sensors)
    recovered: bool = False  # braked, level and above the clearance floor after the pass
    min_alt_after_pass_m: float = math.nan  # lowest altitude after the pass (NaN: no pass)

    def to_json_dict(self) -> dict:
        d = asdict(self)
        for k, v in d.items():
            if isinstance(v, float):
                d[k] = round(v, 6) if math.isfinite(v) else None
        return d


def closest_in_step(r0, r1) -> tuple[float, float, tuple[float, float, float], bool, bool, bool]:
    """Closest approach within one physics step, the relative position moving linearly from
    ``r0`` to ``r1`` (target minus vehicle, m): distance, fraction of the step, the relative
    position there, whether the range was closing at the start, is opening at the end, and is
    still closing at the end (:func:`.physics.closest_approach`, the kernel's own checks)."""
    dist, s, c0, c1, c2, r0d, r1d = closest_approach(
        float(r0[0]), float(r0[1]), float(r0[2]), float(r1[0]), float(r1[1]), float(r1[2])
    )
    return dist, s, (c0, c1, c2), r0d < 0.0, r1d > 0.0, r1d < 0.0
