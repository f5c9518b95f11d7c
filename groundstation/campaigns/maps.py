"""Campaigns beyond the paper's experiments: the envelope map (static targets on a grid of
elevation x azimuth) and the range campaign (acquisition and zero-effort miss at 50-300 m)."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from ..scenario import load_scenario, with_changes
from .aggregate import success_rate
from .cells import group
from .runner import SortieJob

# ------------------------------------------------------------------------- envelope maps
# Static targets on a grid of elevation x azimuth from the nose of a vehicle flying forward
# at 2 m/s from (0, 0, 20) m: each cell is one (elevation, azimuth) direction, each try a range
# drawn in ENVELOPE_RANGE_M. The camera sees +-45 deg x +-36.9 deg.
ENVELOPE_ELEVATIONS_DEG = tuple(float(e) for e in range(-45, 41, 5))
ENVELOPE_AZIMUTHS_DEG = (0.0, 20.0, 40.0)
ENVELOPE_RANGE_M = (15.0, 25.0)
ENVELOPE_START_M = (0.0, 0.0, 20.0)


def envelope_target(elev_deg: float, azim_deg: float, range_m: float) -> tuple[float, ...]:
    """Position of a target at (elevation, azimuth, range) from :data:`ENVELOPE_START_M`,
    azimuth from +y toward +x (DESIGN §1)."""
    e, a = math.radians(elev_deg), math.radians(azim_deg)
    x0, y0, z0 = ENVELOPE_START_M
    return (
        x0 + range_m * math.cos(e) * math.sin(a),
        y0 + range_m * math.cos(e) * math.cos(a),
        z0 + range_m * math.sin(e),
    )


def build_envelope(n, laws, camera, seed, elevations=None, azimuths=None):
    base = load_scenario("static-ahead-20m")
    interceptor = dataclasses.replace(base.interceptor, position_m=ENVELOPE_START_M)
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0xE1E7]))
    jobs = []
    for el in ENVELOPE_ELEVATIONS_DEG if elevations is None else elevations:
        for az in ENVELOPE_AZIMUTHS_DEG if azimuths is None else azimuths:
            for k in range(n):
                r = float(rng.uniform(*ENVELOPE_RANGE_M))
                target = dataclasses.replace(base.target, position_m=envelope_target(el, az, r))
                sc = with_changes(
                    base,
                    name=f"envelope-{el:+.0f}-{az:.0f}",
                    interceptor=interceptor,
                    target=target,
                )
                for law in laws:
                    labels = (("elev_deg", el), ("azim_deg", az), ("law", law), ("try", k))
                    jobs.append(SortieJob(len(jobs), sc, law, seed * 1000 + k, camera, labels))
    return jobs


def cell_stats(outs) -> dict[str, Any]:
    misses = [o.result["miss_m"] for o in outs]
    hits = [o.result["miss_m"] for o in outs if o.result["outcome"] == "HIT"]
    outcomes: dict[str, int] = {}
    for o in outs:
        outcomes[o.result["outcome"]] = outcomes.get(o.result["outcome"], 0) + 1
    return {
        "tries": len(outs),
        "success_rate": success_rate([o.result["outcome"] for o in outs]),
        "cep_m": float(np.median(misses)),
        "hit_cep_m": float(np.median(hits)) if hits else None,
        "max_m": float(np.max(misses)),
        "outcomes": dict(sorted(outcomes.items())),
    }


def summarize_envelope(outcomes):
    """cells[law][elevation][azimuth] -> success rate, CEP, outcomes; ``band`` the elevations
    (per law) whose every azimuth cell has >= 95 % HIT and CEP <= 0.02 m."""
    cells: dict[str, dict[str, dict[str, Any]]] = {}
    for (law, el, az), outs in group(outcomes, "law", "elev_deg", "azim_deg").items():
        cells.setdefault(law, {}).setdefault(f"{el:g}", {})[f"{az:g}"] = cell_stats(outs)
    band = {}
    for law, by_el in cells.items():
        good = [
            float(el)
            for el, by_az in by_el.items()
            if all(c["success_rate"] >= 0.95 and c["cep_m"] <= 0.02 for c in by_az.values())
        ]
        band[law] = good
    return {"cells": cells, "good_elevations_deg": band, "criterion": ">= 95 % HIT, CEP <= 0.02 m"}


# Range: a static target straight ahead of a vehicle flying forward at 2 m/s, within
# RANGE_OFFSET_DEG of its nose, at each range. The acquisition range is the range when the
# loop first tracks; the zero-effort miss (ZEM) is computed from the true states.
RANGES_M = (50, 100, 300)
RANGE_OFFSET_DEG = 3.0
ZEM_LIMIT_M = 1.0


def build_range(n, laws, camera, seed):
    base = load_scenario("static-ahead-20m")
    interceptor = dataclasses.replace(base.interceptor, position_m=ENVELOPE_START_M)
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0x5A46E]))
    jobs = []
    for r in RANGES_M:
        duration = 10.0 + 2.0 * r / 10.0  # time to fly r at ~10 m/s, with margin
        for k in range(n):
            el, az = rng.uniform(-RANGE_OFFSET_DEG, RANGE_OFFSET_DEG, 2)
            target = dataclasses.replace(
                base.target, position_m=envelope_target(float(el), float(az), float(r))
            )
            sc = with_changes(
                base,
                name=f"range-{r}",
                interceptor=interceptor,
                target=target,
                duration_s=duration,
            )
            for law in laws:
                labels = (("range_m", r), ("law", law), ("try", k))
                jobs.append(SortieJob(len(jobs), sc, law, seed * 1000 + k, camera, labels))
    return jobs


def zem_series(trace: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """Zero-effort miss over a sortie from its true states (trace at 50 Hz): with r = target -
    vehicle and v = their velocity difference (the target's from its positions), the miss if
    neither accelerated from now on, |r + v t_go| with t_go = max(-r.v / |v|^2, 0).
    Returns (t_s, zem_m)."""
    t = np.asarray(trace["t_s"], dtype=float)
    r = np.asarray(trace["target_pos_m"], dtype=float) - np.asarray(trace["vehicle_pos_m"])
    if t.size < 2:
        return t, np.linalg.norm(r, axis=1) if r.size else np.zeros(0)
    v_tgt = np.gradient(np.asarray(trace["target_pos_m"], dtype=float), t, axis=0)
    v = v_tgt - np.asarray(trace["vehicle_vel_m_s"], dtype=float)
    vv = np.einsum("ij,ij->i", v, v)
    t_go = np.where(vv > 1e-9, -np.einsum("ij,ij->i", r, v) / np.maximum(vv, 1e-9), 0.0)
    t_go = np.maximum(t_go, 0.0)
    return t, np.linalg.norm(r + v * t_go[:, None], axis=1)


def acquisition(trace: dict[str, Any]) -> tuple[float, float] | None:
    """(time s, range m) of the first traced tick with a target estimate, or None."""
    for i, e in enumerate(trace["e_norm_upright"]):
        if e is not None:
            r = np.subtract(trace["target_pos_m"][i], trace["vehicle_pos_m"][i])
            return float(trace["t_s"][i]), float(np.linalg.norm(r))
    return None


def range_metrics(trace: dict[str, Any]) -> dict[str, Any]:
    """Acquisition range, the ZEM at acquisition, and from when on (s after acquisition) the
    ZEM stays under :data:`ZEM_LIMIT_M` to the end of the sortie, the range then
    (``zem_settle_range_m``) and how long that was before the end (``zem_lead_s``: the
    guidance's margin to spare)."""
    acq = acquisition(trace)
    if acq is None:
        return {
            "acquired": False,
            "acq_range_m": None,
            "zem_acq_m": None,
            "zem_settle_s": None,
            "zem_settle_range_m": None,
            "zem_lead_s": None,
        }
    t, zem = zem_series(trace)
    # up to the pass (the nearest traced sample): after it the vehicle brakes to recover
    rng = np.linalg.norm(np.subtract(trace["target_pos_m"], trace["vehicle_pos_m"]), axis=1)
    end = len(rng) - int(np.argmin(rng[::-1])) if len(rng) else len(t)  # the last nearest
    t, zem = t[:end], zem[:end]
    i0 = int(np.searchsorted(t, acq[0]))
    after = zem[i0:]
    above = np.nonzero(after >= ZEM_LIMIT_M)[0]
    if after.size == 0 or (above.size and above[-1] == after.size - 1):
        settle = None  # still (or again) over the limit at the end
    else:
        settle = 0.0 if above.size == 0 else float(t[i0 + above[-1] + 1] - acq[0])
    settle_range = None
    if settle is not None:
        k = i0 + (0 if above.size == 0 else int(above[-1]) + 1)
        settle_range = float(
            np.linalg.norm(np.subtract(trace["target_pos_m"][k], trace["vehicle_pos_m"][k]))
        )
    return {
        "acquired": True,
        "acq_range_m": acq[1],
        "zem_acq_m": float(after[0]) if after.size else None,
        "zem_settle_s": settle,
        "zem_settle_range_m": settle_range,
        "zem_lead_s": None if settle is None else float(t[-1] - acq[0] - settle),
    }


def summarize_range(outcomes):
    cells: dict[str, dict[str, Any]] = {}
    for (r, law), outs in group(outcomes, "range_m", "law").items():
        mets = [range_metrics(o.trace) for o in outs if o.trace]
        acq = [m for m in mets if m["acquired"]]

        def _med(key, ms=acq):
            vals = [m[key] for m in ms if m[key] is not None]
            return float(np.median(vals)) if vals else None

        settled = [m for m in acq if m["zem_settle_s"] is not None]
        cells.setdefault(str(r), {})[law] = {
            **cell_stats(outs),
            "acquired_rate": len(acq) / len(outs),
            "acq_range_median_m": _med("acq_range_m"),
            "zem_acq_median_m": _med("zem_acq_m"),
            "zem_settle_median_s": _med("zem_settle_s"),
            "zem_settle_range_median_m": _med("zem_settle_range_m"),
            "zem_lead_min_s": min((m["zem_lead_s"] for m in settled), default=None),
            "zem_settled_rate": len(settled) / len(outs),
        }
    return {"cells": cells, "zem_limit_m": ZEM_LIMIT_M}
