"""The paper's experiments as campaigns (DESIGN.md §7): which sorties to run, and what to
make of them. Each campaign is a pair of functions: jobs from (n, laws, camera, seed), and a
summary from the outcomes; the paper's own numbers sit beside ours in the summary."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from onboard.control.guidance import GUIDANCE_LAWS
from onboard.enums import PAPER_LAWS, GuidanceLaw, codes

from ..scenario import load_scenario, with_changes, with_overrides
from . import agility
from .aggregate import median_iqr, miss_stats, success_rate
from .errors import CampaignError
from .runner import SortieJob, SortieOutcome

LAWS = codes(GuidanceLaw)
assert set(LAWS) <= set(GUIDANCE_LAWS)
DEFAULT_LAWS = tuple(m.value for m in PAPER_LAWS)  # flown unless told


# ------------------------------------------------------------------------- paper numbers
PAPER = {
    "static": {"png": 0.089, "ibvs": 0.332, "note": "IBVS = ref. [28]; ref. [26] had 0.457 m"},
    "moving": {
        "cv-top-to-bottom": {"pg": 0.71, "ibvs": 0.27, "png": 0.09},
        "ca-flanking": {"pg": 0.92, "ibvs": 1.76, "png": 0.45},
        "sm-tailgate": {"pg": 0.31, "ibvs": 0.20, "png": 0.04},
    },
    "wind": {  # paper Table 2 (proposed law, 5 real tries per wind speed)
        0: {"success": 1.0, "median_uv": (-0.002, -0.064), "iqr_uv": (0.019, 0.058)},
        2: {"success": 0.8, "median_uv": (-0.010, -0.063), "iqr_uv": (0.046, 0.043)},
        4: {"success": 0.8, "median_uv": (-0.014, -0.060), "iqr_uv": (0.061, 0.057)},
        6: {"success": 0.4, "median_uv": (-0.025, -0.075), "iqr_uv": (0.145, 0.075)},
    },
    "outdoor": {
        "outdoor-static": "intercepted after 6.2 s at 6.3 m/s",
        "outdoor-escape": "intercepted at about 5 m/s; PG and IBVS failed this one",
        "outdoor-takeoff": "intercepted at about 5 m/s",
        "outdoor-circle": "intercepted at about 5 m/s",
    },
}

MOVING_SCENARIOS = ("cv-top-to-bottom", "ca-flanking", "sm-tailgate")
WIND_SPEEDS_M_S = (0, 2, 4, 6)
OUTDOOR_SCENARIOS = ("outdoor-static", "outdoor-escape", "outdoor-takeoff", "outdoor-circle")


@dataclass(frozen=True)
class Campaign:
    name: str
    default_n: int
    what_n_counts: str
    build: Callable[[int, tuple[str, ...], str, int], list[SortieJob]]
    summarize: Callable[[list[SortieOutcome]], dict[str, Any]]


# ------------------------------------------------------------------------- static
# Where static targets are drawn, relative to the nose of a level vehicle facing +y. The
# camera sees +-45 deg x +-36.9 deg. The speed ramp pitches the nose down by atan(k_a / g)
# = 11.5 deg (paper eqs. 14-16) plus a little for drag, which moves every target up in the
# image: a target within ~12 deg of the top edge leaves the view before PNG has turned toward
# it (paper assumption 1, initial visibility). So the upper bound keeps that margin.
STATIC_AZIMUTH_DEG = (-40.0, 40.0)
STATIC_ELEVATION_DEG = (-30.0, 20.0)


def static_targets(n: int, seed: int) -> list[tuple[float, float, float]]:
    """n static targets 15-35 m from (0, 0, 10), inside the camera's view of a vehicle facing
    +y (azimuth and elevation from the nose within the bounds above), at least 1 m up."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0x57A71C]))
    out = []
    while len(out) < n:
        r = rng.uniform(15.0, 35.0)
        az = math.radians(rng.uniform(*STATIC_AZIMUTH_DEG))
        el = math.radians(rng.uniform(*STATIC_ELEVATION_DEG))
        p = (
            r * math.cos(el) * math.sin(az),
            r * math.cos(el) * math.cos(az),
            10.0 + r * math.sin(el),
        )
        if p[2] >= 1.0:
            out.append(p)
    return out


def _build_static(n, laws, camera, seed):
    base = load_scenario("static-ahead-20m")
    jobs = []
    for i, pos in enumerate(static_targets(n, seed)):
        target = dataclasses.replace(base.target, position_m=pos)
        sc = with_changes(base, name=f"static-{i:02d}", target=target)
        for law in laws:
            labels = (("target", i), ("law", law))
            jobs.append(SortieJob(len(jobs), sc, law, seed * 100_000 + i, camera, labels))
    return jobs


def _group(outcomes, *keys):
    groups: dict[tuple, list[SortieOutcome]] = {}
    for o in outcomes:
        groups.setdefault(tuple(o.labels[k] for k in keys), []).append(o)
    return groups


def _summarize_static(outcomes):
    laws = {}
    for (law,), outs in _group(outcomes, "law").items():
        misses = [o.result["miss_m"] for o in outs]
        laws[law] = {
            **miss_stats(misses),
            "success_rate": success_rate([o.result["outcome"] for o in outs]),
            "terminal_speed_mean_m_s": _terminal_speed(outs),
            "paper_cep_m": PAPER["static"].get(law),
        }
    return {"laws": laws, "paper_note": PAPER["static"]["note"]}


# ------------------------------------------------------------------------- moving
def _build_grid(cells, n, laws, camera, seed):
    """Jobs for every (label, scenario name) cell x law x n seeds; the seed of try k is the
    same for every cell and law, so laws are compared on the same noise."""
    jobs = []
    for key, value, name in cells:
        sc = load_scenario(name)
        for law in laws:
            for k in range(n):
                labels = ((key, value), ("law", law), ("try", k))
                jobs.append(SortieJob(len(jobs), sc, law, seed * 1000 + k, camera, labels))
    return jobs


def _build_moving(n, laws, camera, seed):
    return _build_grid([("scenario", s, s) for s in MOVING_SCENARIOS], n, laws, camera, seed)


def _e_samples(outs):
    ex, ey = [], []
    for o in outs:
        for e in o.trace["e_norm_upright"] if o.trace else []:
            if e is not None:
                ex.append(e[0])
                ey.append(e[1])
    return ex, ey


def _summarize_moving(outcomes):
    cells = {}
    for (scenario, law), outs in _group(outcomes, "scenario", "law").items():
        misses = [o.result["miss_m"] for o in outs]
        ex, ey = _e_samples(outs)
        cells.setdefault(scenario, {})[law] = {
            **miss_stats(misses),
            "success_rate": success_rate([o.result["outcome"] for o in outs]),
            "outcomes": sorted({o.result["outcome"] for o in outs}),
            "max_normal_accel_mean_m_s2": float(
                np.mean([o.result["max_normal_accel_m_s2"] for o in outs])
            ),
            "terminal_speed_mean_m_s": _terminal_speed(outs),
            "e_x_median_iqr": median_iqr(ex),
            "e_y_median_iqr": median_iqr(ey),
            "paper_m": PAPER["moving"][scenario].get(law),
        }
    return {"cells": cells}


def _terminal_speed(outs) -> float:
    """The vehicle's mean speed at the closest approach (m/s) over a cell's sorties."""
    return float(np.mean([o.result["terminal_speed_m_s"] for o in outs]))


# ------------------------------------------------------------------------- wind
def _build_wind(n, laws, camera, seed):
    cells = [("wind_m_s", w, f"indoor-tethered-wind-{w}") for w in WIND_SPEEDS_M_S]
    return _build_grid(cells, n, laws, camera, seed)


def _summarize_wind(outcomes):
    cells = {}
    for (w, law), outs in _group(outcomes, "wind_m_s", "law").items():
        ex, ey = _e_samples(outs)
        (mx, ix), (my, iy) = median_iqr(ex), median_iqr(ey)
        cells.setdefault(str(w), {})[law] = {
            "success_rate": success_rate([o.result["outcome"] for o in outs]),
            "tries": len(outs),
            **{f"miss_{k}": v for k, v in miss_stats([o.result["miss_m"] for o in outs]).items()},
            "median_uv": (mx, my),
            "iqr_uv": (ix, iy),
            "terminal_speed_mean_m_s": _terminal_speed(outs),
        }
    return {"cells": cells, "paper": {str(w): PAPER["wind"][w] for w in WIND_SPEEDS_M_S}}


# ------------------------------------------------------------------------- outdoor
def _build_outdoor(n, laws, camera, seed):
    return _build_grid([("scenario", s, s) for s in OUTDOOR_SCENARIOS], n, laws, camera, seed)


def _summarize_outdoor(outcomes):
    cells = {}
    for (scenario, law), outs in _group(outcomes, "scenario", "law").items():
        cells.setdefault(scenario, {})[law] = {
            **miss_stats([o.result["miss_m"] for o in outs]),
            "success_rate": success_rate([o.result["outcome"] for o in outs]),
            "terminal_speed_mean_m_s": _terminal_speed(outs),
            "intercept_time_mean_s": float(np.mean([o.result["intercept_time_s"] for o in outs])),
            "paper": PAPER["outdoor"][scenario] if law == "png" else None,
        }
    return {"cells": cells}


# ------------------------------------------------------------------------- drag
# The two sorties that need the speed ramp to beat the airframe's drag (docs/air.md), each
# sortie's drag drawn in this range (N s/m-equivalent at 10 m/s): the loop believes only k_drag.
DRAG_SCENARIOS = ("fast-crossing-50m", "climbing-turn")
DRAG_RANGE_N_S_M = (0.25, 0.5)


def _build_drag(n, laws, camera, seed):
    jobs = _build_grid([("scenario", s, s) for s in DRAG_SCENARIOS], n, laws, camera, seed)
    lo, hi = DRAG_RANGE_N_S_M
    ranged = {"interceptor.drag_min_n_s_m": lo, "interceptor.drag_max_n_s_m": hi}
    drawn = {name: with_overrides(load_scenario(name), ranged) for name in DRAG_SCENARIOS}
    return [dataclasses.replace(j, scenario=drawn[dict(j.labels)["scenario"]]) for j in jobs]


def _summarize_drag(outcomes):
    cells = {}
    for (scenario, law), outs in _group(outcomes, "scenario", "law").items():
        cells.setdefault(scenario, {})[law] = {
            **miss_stats([o.result["miss_m"] for o in outs]),
            "success_rate": success_rate([o.result["outcome"] for o in outs]),
            "outcomes": sorted({o.result["outcome"] for o in outs}),
            "terminal_speed_mean_m_s": _terminal_speed(outs),
            "intercept_time_mean_s": float(np.mean([o.result["intercept_time_s"] for o in outs])),
            "paper": None,
        }
    return {"cells": cells, "drag_range_n_s_m": DRAG_RANGE_N_S_M}


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


def _build_envelope(n, laws, camera, seed, elevations=None, azimuths=None):
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


def _cell_stats(outs) -> dict[str, Any]:
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


def _summarize_envelope(outcomes):
    """cells[law][elevation][azimuth] -> success rate, CEP, outcomes; ``band`` the elevations
    (per law) whose every azimuth cell has >= 95 % HIT and CEP <= 0.02 m."""
    cells: dict[str, dict[str, dict[str, Any]]] = {}
    for (law, el, az), outs in _group(outcomes, "law", "elev_deg", "azim_deg").items():
        cells.setdefault(law, {}).setdefault(f"{el:g}", {})[f"{az:g}"] = _cell_stats(outs)
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


def _build_range(n, laws, camera, seed):
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


def _summarize_range(outcomes):
    cells: dict[str, dict[str, Any]] = {}
    for (r, law), outs in _group(outcomes, "range_m", "law").items():
        mets = [range_metrics(o.trace) for o in outs if o.trace]
        acq = [m for m in mets if m["acquired"]]

        def _med(key, ms=acq):
            vals = [m[key] for m in ms if m[key] is not None]
            return float(np.median(vals)) if vals else None

        settled = [m for m in acq if m["zem_settle_s"] is not None]
        cells.setdefault(str(r), {})[law] = {
            **_cell_stats(outs),
            "acquired_rate": len(acq) / len(outs),
            "acq_range_median_m": _med("acq_range_m"),
            "zem_acq_median_m": _med("zem_acq_m"),
            "zem_settle_median_s": _med("zem_settle_s"),
            "zem_settle_range_median_m": _med("zem_settle_range_m"),
            "zem_lead_min_s": min((m["zem_lead_s"] for m in settled), default=None),
            "zem_settled_rate": len(settled) / len(outs),
        }
    return {"cells": cells, "zem_limit_m": ZEM_LIMIT_M}


CAMPAIGNS: dict[str, Campaign] = {
    "static": Campaign("static", 50, "targets", _build_static, _summarize_static),
    "moving": Campaign("moving", 10, "seeds per cell", _build_moving, _summarize_moving),
    "wind": Campaign("wind", 20, "tries per wind speed", _build_wind, _summarize_wind),
    "outdoor": Campaign("outdoor", 5, "seeds per cell", _build_outdoor, _summarize_outdoor),
    "drag": Campaign("drag", 20, "seeds per scenario", _build_drag, _summarize_drag),
    "envelope": Campaign(
        "envelope", 20, "tries per elevation x azimuth cell", _build_envelope, _summarize_envelope
    ),
    "range": Campaign("range", 20, "tries per range", _build_range, _summarize_range),
    "agility": Campaign(
        "agility", 20, "tries per acceleration / jink range", agility.build, agility.summarize
    ),
}


def parse_laws(text: str) -> tuple[str, ...]:
    laws = tuple(x.strip() for x in text.split(",") if x.strip())
    if not laws:
        raise CampaignError("--laws needs at least one law")
    bad = [x for x in laws if x not in LAWS]
    if bad:
        raise CampaignError(f"unknown law(s) {', '.join(bad)}; choose from {', '.join(LAWS)}")
    if len(set(laws)) != len(laws):
        raise CampaignError("--laws lists a law twice")
    return laws


def get_campaign(name: str) -> Campaign:
    if name not in CAMPAIGNS:
        raise CampaignError(f"unknown campaign {name!r}; choose one of {', '.join(CAMPAIGNS)}")
    return CAMPAIGNS[name]


def build_jobs(
    name: str, n: int | None = None, laws=DEFAULT_LAWS, camera="projected", seed=0
) -> list[SortieJob]:
    campaign = get_campaign(name)
    n = campaign.default_n if n is None else n
    if n < 1:
        raise CampaignError("--n must be at least 1")
    return campaign.build(n, tuple(laws), camera, seed)
