"""What a better estimate of the target's acceleration can gain:
``python -m groundstation.bench.agility_bound --kind turn --value 5 --n 10 --seed 0``.

Flies the sorties of one cell of the ``agility`` campaign (the same draws and seeds as
``groundstation campaign agility --n N --seed S``) with the augmented law twice: as the
vehicle flies it (the IMM's estimate), and with the IMM's acceleration replaced, whenever the
true time to go is under ``--last-s``, by the target's true acceleration (ideal sensors,
analysis only: the bound on what a perfect estimate gains), optionally scaled (``--scale``,
an estimate that holds that share of the truth) or late (``--delay-s``, one that lags), with
the truth's turn rate (which the law flies with the gain ``t_turn`` > 0: ``--set
gains.t_turn=1.5``). The IMM's velocity (time to go) and everything else the loop sees stay
as they are. ``--imm KEY=VALUE`` changes a field of the IMM's
:class:`~onboard.estimation.imm.ImmConfig` and ``--set SECTION.KEY=VALUE`` a scenario value,
for both. Prints HIT count and mean miss of each.

A measuring tool beside the product: it reads the simulator's truth, which the loop never does.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

IDEAL_LABEL = "truth acceleration (ideal, analysis only)"


@dataclass
class TruthAccel:
    """The target's true acceleration (m/s^2 ENU) from its true velocity at successive control
    ticks, ``delay_s`` late and times ``scale``."""

    delay_s: float = 0.0
    scale: float = 1.0
    _last: tuple[float, np.ndarray] | None = None
    _held: deque = field(default_factory=deque)

    def step(self, t: float, velocity_enu_m_s) -> np.ndarray:
        """The acceleration to hand the law at ``t`` (s) given the target's true velocity
        then (m/s ENU): the finite difference since the previous tick, ``delay_s`` ago (zero
        before there is one that old), times ``scale``."""
        v = np.array(velocity_enu_m_s, dtype=float)
        a = np.zeros(3)
        if self._last is not None and t > self._last[0]:
            a = (v - self._last[1]) / (t - self._last[0])
        self._last = (t, v)
        self._held.append((t, a))
        due = t - self.delay_s + 1e-9
        while len(self._held) > 1 and self._held[1][0] <= due:
            self._held.popleft()
        first_t, first_a = self._held[0]
        out = first_a if first_t <= due else np.zeros(3)
        return self.scale * out


def true_time_to_go_s(sim) -> float:
    """Range over closing speed (s) from the simulator's truth; inf when not closing."""
    rel = np.array(sim.target.p) - np.array(sim.vehicle.x[0:3])
    dv = np.array(sim.vehicle.x[3:6]) - np.array(sim.target.v)
    r = float(np.linalg.norm(rel))
    closing = float(dv @ rel) / r if r > 0.0 else 0.0
    return r / closing if closing > 0.0 else math.inf


def fly(job, last_s: float | None, scale: float = 1.0, delay_s: float = 0.0, imm=None):
    """One sortie of ``job``; with ``last_s`` the law is handed the truth's acceleration
    (:class:`TruthAccel`) and turn rate while the true time to go is under it; ``imm`` an
    ImmConfig for the loop's IMM (None: its own). Returns its SortieResult."""
    from onboard.estimation.imm import MotionEstimate, TargetMotionImm, turn_rate_rad_s

    from ..sim.simulation import Simulation

    sim = Simulation(job.scenario, job.law, job.seed, job.camera, keep_records=False)
    if imm is not None:
        sim.loop.motion = TargetMotionImm(imm)
    if last_s is None:
        return sim.run()
    loop = sim.loop
    track = loop._track_motion
    truth = TruthAccel(delay_s, scale)

    def with_truth(t, est, state, R_WB, gyro):
        e = track(t, est, state, R_WB, gyro)
        a = truth.step(t, sim.target.v)
        if e is None or not true_time_to_go_s(sim) < last_s:
            return e
        a_t = (float(a[0]), float(a[1]), float(a[2]))
        omega = turn_rate_rad_s(sim.target.v, a, math.inf)
        return MotionEstimate(t, a_t, e.velocity_enu_m_s, 0.0, e.probabilities, omega)

    loop._track_motion = with_truth
    return sim.run()


def cell_jobs(kind: str, value: float, n: int, seed: int, overrides=None) -> list:
    """The augmented law's jobs of one cell of the agility campaign, with the scenario
    ``overrides`` (``{"estimate.lag_s": 0.02}``) applied."""
    from ..campaigns import agility
    from ..scenario import with_overrides

    jobs = agility.build(n, ("apn",), "projected", seed)
    out = [j for j in jobs if dict(j.labels)["kind"] == kind and dict(j.labels)["value"] == value]
    if not out:
        raise ValueError(f"the agility campaign has no cell kind={kind} value={value:g}")
    return [
        dataclasses.replace(j, scenario=with_overrides(j.scenario, overrides or {})) for j in out
    ]


def imm_config(items: list[str] | None):
    """An ImmConfig with ``KEY=VALUE`` items (float fields) changed; None without items."""
    from onboard.estimation.imm import ImmConfig

    if not items:
        return None
    fields = {f.name for f in dataclasses.fields(ImmConfig) if f.type in ("float", float)}
    changes = {}
    for item in items:
        key, _, text = item.partition("=")
        if key not in fields:
            raise ValueError(
                f"--imm {item!r}: the IMM's float fields are {', '.join(sorted(fields))}"
            )
        try:
            changes[key] = float(text)
        except ValueError:
            raise ValueError(f"--imm {item!r}: {text!r} is not a number") from None
        if not math.isfinite(changes[key]):
            raise ValueError(f"--imm {item!r}: not a finite number")
    return ImmConfig(**changes)


def cell_parser(description: str) -> argparse.ArgumentParser:
    """The options that name one cell of the agility campaign and the IMM to fly it with
    (this bench and ``groundstation.bench.imm_lag``)."""
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--kind", choices=("turn", "jink"), default="turn")
    ap.add_argument("--value", type=float, default=5.0, help="the cell: m/s^2 or jink range m")
    ap.add_argument("--n", type=int, default=10, help="tries of the cell (the campaign's --n)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--imm", action="append", metavar="KEY=VALUE", help="an ImmConfig field")
    ap.add_argument("--set", action="append", metavar="SECTION.KEY=VALUE", help="a scenario value")
    return ap


def cell_of(ap: argparse.ArgumentParser, args: argparse.Namespace) -> tuple:
    """The IMM configuration and the jobs :func:`cell_parser`'s options name (with their
    ``--set`` scenario values); a bad one is ``ap``'s usage error."""
    from ..scenario import parse_overrides

    if args.n < 1:
        ap.error("--n must be at least 1")
    if not (math.isfinite(args.value) and args.value >= 0.0):
        ap.error("--value must be a finite number >= 0")
    try:
        overrides = parse_overrides(args.set)
        return imm_config(args.imm), cell_jobs(args.kind, args.value, args.n, args.seed, overrides)
    except ValueError as e:
        ap.error(str(e))


def main(argv: list[str] | None = None) -> int:
    ap = cell_parser(__doc__.splitlines()[0])
    ap.add_argument("--last-s", type=float, default=1.5, help="truth within this time to go")
    ap.add_argument("--scale", type=float, default=1.0, help="share of the truth handed over")
    ap.add_argument("--delay-s", type=float, default=0.0, help="the truth this late (s)")
    args = ap.parse_args(argv)
    for name in ("last_s", "scale", "delay_s"):
        x = getattr(args, name)
        if not (math.isfinite(x) and x >= 0.0):
            ap.error(f"--{name.replace('_', '-')} must be a finite number >= 0")
    imm, jobs = cell_of(ap, args)
    print(f"agility {args.kind} {args.value:g}, APN, seed {args.seed}, {len(jobs)} sorties")
    runs = (
        ("IMM (as flown)", None),
        (
            f"{IDEAL_LABEL} x {args.scale:g}, {args.delay_s:g} s late, within t_go "
            f"{args.last_s:g} s",
            args.last_s,
        ),
    )
    for label, last_s in runs:
        results = [fly(j, last_s, args.scale, args.delay_s, imm) for j in jobs]
        hits = sum(r.outcome == "HIT" for r in results)
        mean = float(np.mean([r.miss_m for r in results]))
        print(f"{label}: {hits}/{len(results)} HIT, mean miss {mean:.2f} m")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
