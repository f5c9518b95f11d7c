"""Reference sortie outcomes for tests/test_speed_regression.py.

``python -m tests.speed_reference`` rewrites tests/data/speed_reference.json from the code as
it is. Regenerate it only when a change is meant to alter the flown numbers, and say so in
the commit: a change meant only to be faster (or tidier) must fly the same sorties.
"""

from __future__ import annotations

import json
from pathlib import Path

REFERENCE_PATH = Path(__file__).parent / "data" / "speed_reference.json"

# (scenario, law, seed, camera): static, moving, windy and takeoff cases, all three laws and
# both camera modes; about 2 s of computing in all.
CASES = (
    ("static-ahead-20m", "png", 0, "projected"),
    ("static-left-low-15m", "pg", 1, "projected"),
    ("cv-top-to-bottom", "png", 3, "projected"),
    ("cv-top-to-bottom", "ibvs", 2, "projected"),
    ("ca-flanking", "png", 4, "projected"),
    ("outdoor-escape", "pg", 5, "projected"),
    ("outdoor-takeoff", "png", 6, "projected"),
    ("indoor-tethered-wind-4", "png", 7, "projected"),
    ("cv-top-to-bottom", "png", 0, "rendered"),
)

FIELDS = (
    "outcome",
    "miss_m",
    "intercept_time_s",
    "terminal_speed_m_s",
    "max_normal_accel_m_s2",
    "sim_time_s",
    "detections_fused",
    "detections_rejected",
    "guard_trips",
)


def compute(case: tuple[str, str, int, str]) -> dict:
    """One case's outcome, miss and the other result figures, plus the vehicle's final state."""
    from groundstation.scenario import load_scenario
    from groundstation.sim.simulation import Simulation

    name, law, seed, camera = case
    sim = Simulation(load_scenario(name), law, seed, camera, keep_records=False)
    res = sim.run()
    out = {k: getattr(res, k) for k in FIELDS}
    out["final_p_enu_m"] = [float(c) for c in sim.vehicle.p]
    out["final_v_enu_m_s"] = [float(c) for c in sim.vehicle.v]
    out["final_q_wxyz"] = [float(c) for c in sim.vehicle.q]
    return out


def main() -> None:
    data = [{"case": list(c), "result": compute(c)} for c in CASES]
    REFERENCE_PATH.write_text(json.dumps(data, indent=1) + "\n")
    print(f"wrote {REFERENCE_PATH} ({len(data)} cases)")


if __name__ == "__main__":
    main()
