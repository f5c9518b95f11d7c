"""Running many sorties: a job is everything one sortie needs (scenario, law, seed, camera),
so it runs the same anywhere; a runner maps jobs to outcomes. :class:`LocalPoolRunner` uses a
process pool on this machine; another engine (a cluster) only has to implement
:class:`SortieRunner`. Results come back in job order, so they do not depend on the workers.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from onboard.control.guidance import normal_component

from ..recording.writer import SortieRecorder
from ..scenario import Scenario
from ..sim.camera import sphere_in_view
from ..sim.simulation import Simulation
from .pool import default_workers, pool_context

TRACE_EVERY_TICKS = 2  # 50 Hz at the default 100 Hz control rate


@dataclass(frozen=True)
class SortieJob:
    index: int
    scenario: Scenario
    law: str
    seed: int
    camera: str = "projected"
    labels: tuple[tuple[str, Any], ...] = ()
    trace: bool = True
    log_dir: str | None = None  # record the sortie there (MCAP)


@dataclass
class SortieOutcome:
    index: int
    labels: dict[str, Any]
    result: dict[str, Any]  # SortieResult.to_json_dict()
    trace: dict[str, Any] | None = field(default=None, repr=False)


def saturated_fraction(sim: Simulation) -> float:
    """Share of control ticks with a command at a limit: |a_d| at a_max (eq. 17), |omega| at
    omega_max (eq. 24) or thrust clipped to 0 or full (eq. 23). Needs the sortie's records."""
    if not sim.records:
        return 0.0
    g = sim.loop.gains
    a_lim, w_lim = 0.999 * g.a_max, 0.999 * g.omega_max
    n = 0
    for rec in sim.records:
        tel = rec.telemetry
        thrust = tel.command.thrust_normalised
        n += (
            _norm3(tel.accel_desired_enu_m_s2) >= a_lim
            or _norm3(tel.command.body_rates_flu_rad_s) >= w_lim
            or not 0.001 < thrust < 0.999
        )
    return n / len(sim.records)


def _norm3(v) -> float:
    """|v| of a 3-vector in floats (what np.linalg.norm computes, without its call cost)."""
    x, y, z = v.tolist() if isinstance(v, np.ndarray) else v
    return math.sqrt(x * x + y * y + z * z)


def _trace(sim: Simulation, initial_px: tuple[float, float] | None) -> dict[str, Any]:
    """Time series for plots, as plain lists (picklable, JSON-able)."""
    f = sim.camera_model.f_px
    t, veh, tgt, vel, a_n, v_n, e = [], [], [], [], [], [], []
    for rec in sim.records[::TRACE_EVERY_TICKS]:
        t.append(round(rec.time_s, 4))
        veh.append([round(c, 4) for c in rec.vehicle_p_enu_m])
        tgt.append([round(c, 4) for c in rec.target_p_enu_m])
        vel.append([round(c, 4) for c in rec.vehicle_v_enu_m_s])
        a_n.append(round(rec.normal_accel_m_s2, 4))
        tp, vp = rec.target_p_enu_m, rec.vehicle_p_enu_m
        los = (tp[0] - vp[0], tp[1] - vp[1], tp[2] - vp[2])
        v_n.append(round(normal_component(rec.vehicle_v_enu_m_s, los), 4))
        est = rec.telemetry.e_est_px
        if est is None:
            e.append(None)
        else:
            ux, uy = sim.camera_model.upright(*est)
            e.append([round(ux / f, 5), round(uy / f, 5)])
    return {
        "t_s": t,
        "vehicle_pos_m": veh,
        "target_pos_m": tgt,
        "vehicle_vel_m_s": vel,
        "normal_accel_m_s2": a_n,
        "normal_vel_m_s": v_n,
        "e_norm_upright": e,
        "closest_rel_m": [round(c, 5) for c in sim.closest_rel_m],
        "closest_vel_m_s": [round(c, 4) for c in sim.closest_vel_m_s],
        "initial_px": None if initial_px is None else [round(c, 2) for c in initial_px],
        "saturated_fraction": round(saturated_fraction(sim), 5),
    }


def run_job(job: SortieJob) -> SortieOutcome:
    """Run one sortie (in whatever process) and return its outcome."""
    observers = [] if job.log_dir is None else [SortieRecorder(Path(job.log_dir))]
    sim = Simulation(  # the trace reads no DKF state: frames skip it (and its covariance)
        job.scenario,
        job.law,
        job.seed,
        job.camera,
        keep_records=job.trace,
        observers=observers,
        records_dkf=False,
    )
    initial_px = sphere_in_view(
        sim.camera_model, sim.R_WC(), sim.vehicle.p, sim.target.p, sim.scenario.target.diameter_m
    )[0]
    result = sim.run().to_json_dict()
    trace = _trace(sim, initial_px) if job.trace else None
    return SortieOutcome(job.index, dict(job.labels), result, trace)


class SortieRunner(Protocol):
    def run(
        self,
        jobs: Sequence[SortieJob],
        on_done: Callable[[SortieOutcome], None] | None = None,
    ) -> list[SortieOutcome]:
        """Run every job; return the outcomes in job order."""
        ...


class LocalPoolRunner:
    """A process pool on this machine (``workers == 1`` runs in this process)."""

    def __init__(self, workers: int | None = None) -> None:
        self.workers = workers or default_workers()
        if self.workers < 1:
            raise ValueError("workers must be at least 1")
        self._pool: ProcessPoolExecutor | None = None

    def __enter__(self) -> LocalPoolRunner:
        """Keep one pool over several :meth:`run` calls (a tuning study's trials)."""
        if self.workers > 1 and self._pool is None:
            self._pool = ProcessPoolExecutor(self.workers, mp_context=pool_context())
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None

    def run(
        self,
        jobs: Sequence[SortieJob],
        on_done: Callable[[SortieOutcome], None] | None = None,
    ) -> list[SortieOutcome]:
        outcomes: list[SortieOutcome] = []
        if self.workers == 1 or len(jobs) <= 1:
            for job in jobs:
                out = run_job(job)
                outcomes.append(out)
                if on_done:
                    on_done(out)
        else:
            pool = self._pool or ProcessPoolExecutor(self.workers, mp_context=pool_context())
            try:
                futures = [pool.submit(run_job, job) for job in jobs]
                for fut in as_completed(futures):
                    out = fut.result()
                    outcomes.append(out)
                    if on_done:
                        on_done(out)
            finally:
                if pool is not self._pool:
                    pool.shutdown()
        outcomes.sort(key=lambda o: o.index)
        return outcomes
