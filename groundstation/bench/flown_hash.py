"""``python -m groundstation.bench.flown_hash``: one hash of what the loop flew, to show that a
change meant to be bit-identical is (run it on both trees and compare the lines).

Flies 42 projected-camera sorties (seven scenarios: static, moving, takeoff, escape, tethered
in wind; the three laws; two seeds) and hashes, per sortie, every control tick's telemetry
(LOS and velocity angles, desired acceleration and its normal component, yaw rate, body rates,
thrust) and the result; prints one line per sortie and the hash of them all. About a minute.
"""

from __future__ import annotations

import hashlib
import struct

import numpy as np

from onboard.enums import GuidanceLaw

from ..scenario import load_scenario
from ..sim.simulation import Simulation

SCENARIOS = (
    "static-ahead-20m",
    "static-left-low-15m",
    "cv-top-to-bottom",
    "ca-flanking",
    "outdoor-escape",
    "outdoor-takeoff",
    "indoor-tethered-wind-4",
)


def sortie_hash(scenario: str, law: str, seed: int) -> str:
    """The hex digest of one sortie's tick telemetry and result."""
    sim = Simulation(load_scenario(scenario), law, seed, "projected", keep_records=True)
    result = sim.run()
    h = hashlib.sha256()
    for rec in sim.records:
        t = rec.telemetry
        vals = [
            t.time_s,
            t.los_elev_rad,
            t.los_azim_rad,
            t.vel_elev_rad,
            t.vel_azim_rad,
            t.accel_normal_desired_m_s2,
            t.yaw_rate_cmd_rad_s,
            t.command.thrust_normalised,
            *np.asarray(t.accel_desired_enu_m_s2, dtype=float).tolist(),
            *np.asarray(t.command.body_rates_flu_rad_s, dtype=float).tolist(),
        ]
        h.update(struct.pack(f"{len(vals)}d", *vals))
    h.update(repr(result.to_json_dict()).encode())
    return h.hexdigest()


def main() -> None:
    total = hashlib.sha256()
    for scenario in SCENARIOS:
        for law in GuidanceLaw:
            for seed in (0, 1):
                digest = sortie_hash(scenario, law.value, seed)
                total.update(bytes.fromhex(digest))
                print(scenario, law.value, seed, digest[:12], flush=True)
    print("all", total.hexdigest()[:16])


if __name__ == "__main__":
    main()
