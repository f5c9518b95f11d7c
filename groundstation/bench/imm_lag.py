"""How late and how much of a manoeuvre the IMM sees in flight:
``python -m groundstation.bench.imm_lag --kind turn --value 5 --n 10 --seed 0``.

Flies the sorties of one cell of the ``agility`` campaign (the same draws and seeds as
``groundstation campaign agility --n N --seed S``) with the augmented law, as the vehicle flies
it, and prints per band of true time to go: the share of the target's true acceleration across
the true line of sight that the IMM's estimate holds (sum a_est . a_true / sum |a_true|^2), and
the delay d at which the truth d seconds earlier fits the estimate best with the share it then
holds; then per band of range the median 1-sigma across and along the line of sight of the
position the IMM is fed, its DKF part and the vehicle pose's part (``ImmConfig``'s
``pose_position_sigma_m`` and ``pose_attitude_sigma_deg``) apart. ``--imm KEY=VALUE`` changes
a field of the IMM's configuration as in ``groundstation.bench.agility_bound``.

A measuring tool beside the product: it reads the simulator's truth, which the loop never does.
"""

from __future__ import annotations

import math

import numpy as np

from .agility_bound import TruthAccel, cell_of, cell_parser, true_time_to_go_s

TGO_BANDS_S = ((0.0, 1.0), (1.0, 2.0), (2.0, 3.0))
RANGE_BANDS_M = ((0.0, 5.0), (5.0, 10.0), (10.0, 20.0), (20.0, 40.0))
DELAYS_S = tuple(0.05 * k for k in range(33))  # 0-1.6 s


def share_and_delay(runs: list[np.ndarray], lo: float, hi: float) -> tuple[float, float, float]:
    """Rows (t s, t_go s, a_true across (3), a_est across (3)) of each sortie: within
    lo <= t_go < hi, the share of the truth the estimate holds, and the delay (s, of
    :data:`DELAYS_S`) whose late truth it fits best with that fit's share."""

    def fit(d: float) -> float:
        num = den = 0.0
        for R in runs:
            m = (R[:, 1] >= lo) & (R[:, 1] < hi)
            late = np.stack([np.interp(R[m, 0] - d, R[:, 0], R[:, 2 + k]) for k in range(3)], 1)
            num += float(np.sum(late * R[m, 5:8]))
            den += float(np.sum(late * late))
        return num / den if den > 0.0 else math.nan

    share = fit(0.0)
    best = max(DELAYS_S, key=lambda d: -math.inf if math.isnan(fit(d)) else fit(d))
    return share, best, fit(best)


def fly_recorded(job, imm=None) -> tuple[np.ndarray, list[tuple[float, float, float, float]]]:
    """One sortie of ``job`` as flown: its rows for :func:`share_and_delay` (ticks with an IMM
    estimate) and, per position fed to the IMM, (range m, DKF across m, pose across m, DKF
    along m)."""
    from onboard.estimation.imm import TargetMotionImm, pose_covariance_m2

    from ..sim.simulation import Simulation

    sim = Simulation(job.scenario, job.law, job.seed, job.camera, keep_records=False)
    loop = sim.loop
    if imm is not None:
        loop.motion = TargetMotionImm(imm)
    motion, track, truth = loop.motion, loop._track_motion, TruthAccel()
    rows, fed = [], []
    update = motion.update

    def measured(t, p, cov, v=None, cam=None):
        if cam is not None:
            rel = np.asarray(p) - np.asarray(cam)
            r = float(np.linalg.norm(rel))
            if r > 0.0 and np.isfinite(cov).all():
                n = rel / r
                across = np.eye(3) - np.outer(n, n)
                pose = pose_covariance_m2(rel, motion.config)
                fed.append(
                    (
                        r,
                        math.sqrt(max(np.trace(across @ cov @ across) / 2.0, 0.0)),
                        math.sqrt(max(np.trace(across @ pose @ across) / 2.0, 0.0)),
                        math.sqrt(max(float(n @ cov @ n), 0.0)),
                    )
                )
        return update(t, p, cov, v, cam)

    def recorded(t, est, state, R_WB, gyro):
        e = track(t, est, state, R_WB, gyro)
        a = truth.step(t, sim.target.v)
        if e is not None:
            los = np.array(sim.target.p) - np.array(sim.vehicle.x[0:3])
            los /= np.linalg.norm(los)
            across = np.eye(3) - np.outer(los, los)
            a_est = across @ np.array(e.accel_enu_m_s2)
            rows.append((t, true_time_to_go_s(sim), *(across @ a), *a_est))
        return e

    motion.update, loop._track_motion = measured, recorded
    sim.run()
    return np.array(rows).reshape(-1, 8), fed


def main(argv: list[str] | None = None) -> int:
    ap = cell_parser(__doc__.splitlines()[0])
    args = ap.parse_args(argv)
    imm, jobs = cell_of(ap, args)
    print(f"agility {args.kind} {args.value:g}, APN, seed {args.seed}, {len(jobs)} sorties")
    runs, fed = [], []
    for job in jobs:
        rows, f = fly_recorded(job, imm)
        if len(rows):
            runs.append(rows)
        fed.extend(f)
    for lo, hi in TGO_BANDS_S:
        share, d, fit = share_and_delay(runs, lo, hi)
        print(
            f"t_go {lo:g}-{hi:g} s: the estimate holds {share:.2f} of the true acceleration "
            f"across the line of sight; best fit {fit:.2f} of it {d:.2f} s late"
        )
    F = np.array(fed).reshape(-1, 4)
    for lo, hi in RANGE_BANDS_M:
        m = (F[:, 0] >= lo) & (F[:, 0] < hi)
        if m.any():
            dkf, pose, along = (float(np.median(F[m, k])) for k in (1, 2, 3))
            print(
                f"range {lo:g}-{hi:g} m: position fed 1-sigma across the line of sight "
                f"{dkf:.3f} m (DKF) and {pose:.3f} m (pose), along {along:.2f} m "
                f"({int(m.sum())} updates)"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
