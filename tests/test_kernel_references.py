"""Every kernel agrees with its reference, the readable statement of its maths in the paper's
notation (``*_reference.py`` beside each kernel module; tests/kernel_cases.py pairs them).

The arguments are the ones the kernels saw in recorded sorties (a static target with each
guidance law, an escaping target with the LOS low-pass and the midcourse term on, a tethered
balloon in a gusty fan jet): up to ``SAMPLES`` calls of each kernel, drawn at random (seeded)
from all its calls, each also perturbed ``PERTURBED`` times (seeded: floats and small float
vectors by 1 % relative, rotation matrices by a small rotation, unit quaternions kept unit;
times, indices, flags and buffers untouched). Tolerance: rtol 1e-9, atol 1e-12, the same
float64 operations done in another order (numpy's matrix products, vector norms; the
turbulence's sum over about 100 modes, taken in order by the kernel, compiled or as numpy, and
by matrix products in its reference). Runs as Python or compiled, as the process is
(``PEREGRINE_JIT``).

The helper kernels without a reference of their own are listed in
``kernel_cases.COVERED`` with the reference that covers them: Python's ``min``/``max``
(``_min``/``_max``), Dekker's exact square inside ``hypot2`` (checked against
``math.hypot``), the Gauss-Markov and random-walk one-liners inside ``advance_errors``."""

from __future__ import annotations

import copy
import importlib
import math
import re
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from onboard import jit
from tests import kernel_cases, kernel_cases_sim  # noqa: F401 (the simulator's cases)

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = 25
PERTURBED = 2
RTOL, ATOL = 1e-9, 1e-12


def _kernel_modules() -> list[str]:
    """Every module of the package that defines a kernel (found in the sources, so that a new
    kernel module cannot hide from this test)."""
    names = []
    for path in sorted(
        [*ROOT.joinpath("onboard").rglob("*.py"), *ROOT.joinpath("groundstation").rglob("*.py")]
    ):
        if re.search(r"^@kernel\b", path.read_text(encoding="utf-8"), re.M):
            names.append(".".join(path.relative_to(ROOT).with_suffix("").parts))
    return names


def _all_kernels() -> dict[str, object]:
    for name in _kernel_modules():
        importlib.import_module(name)
    out = {}
    for k in jit.KERNELS:
        fn = getattr(k, "py_func", k)
        out[f"{fn.__module__}.{fn.__name__}"] = k
    return out


KERNELS = _all_kernels()


def test_every_kernel_has_a_reference():
    missing = sorted(set(KERNELS) - set(kernel_cases.CASES) - set(kernel_cases.COVERED))
    assert not missing, f"kernels without a registered reference: {missing}"
    stale = sorted((set(kernel_cases.CASES) | set(kernel_cases.COVERED)) - set(KERNELS))
    assert not stale, f"references registered for kernels that do not exist: {stale}"
    assert not set(kernel_cases.CASES) & set(kernel_cases.COVERED)


# ---------------------------------------------------------------- recording
class _Recorder:
    """Seeded reservoir samples of each kernel's arguments (copied when kept)."""

    def __init__(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)
        self.calls: Counter[str] = Counter()
        self.kept: dict[str, list[tuple]] = {}

    def wrap(self, name: str, fn):
        def recording(*args):
            c = self.calls[name]
            self.calls[name] = c + 1
            kept = self.kept.setdefault(name, [])
            if c < SAMPLES:
                kept.append(copy.deepcopy(args))
            else:
                slot = int(self.rng.integers(0, c + 1))
                if slot < SAMPLES:
                    kept[slot] = copy.deepcopy(args)
            return fn(*args)

        return recording


def _record(monkeypatch_ctx) -> _Recorder:
    """Fly the sorties with every kernel's Python source behind a recording wrapper (its
    module's name for it, so that kernels calling kernels are recorded too)."""
    from groundstation.scenario import SCENARIO_DIR, load_scenario
    from groundstation.sim.simulation import Simulation
    from onboard.gains import Gains

    rec = _Recorder(seed=37)
    by_id = {id(k): name for name, k in KERNELS.items()}
    import sys

    for mod_name, mod in list(sys.modules.items()):
        if not mod_name.startswith(("onboard", "groundstation")) or mod is None:
            continue
        for attr, value in list(vars(mod).items()):
            name = by_id.get(id(value))
            if name is not None:
                fn = getattr(value, "py_func", value)
                monkeypatch_ctx.setattr(mod, attr, rec.wrap(name, fn))
    sorties = [
        ("static-ahead-20m", "png", None),
        ("static-ahead-20m", "pg", None),
        ("static-ahead-20m", "ibvs", None),
        ("outdoor-escape", "png", Gains(tau_los=0.05, r_mid=8.0)),
        ("indoor-tethered-wind-4", "png", None),
    ]
    for scenario, law, gains in sorties:
        sc = load_scenario(SCENARIO_DIR / f"{scenario}.toml")
        Simulation(sc, law, 1, "projected", gains=gains, keep_records=False).run()
    return rec


@pytest.fixture(scope="module")
def recorded():
    mp = pytest.MonkeyPatch()
    try:
        rec = _record(mp)
    finally:
        mp.undo()
    return rec


# ---------------------------------------------------------------- perturbation
def _is_rotation(a: np.ndarray) -> bool:
    return a.shape == (3, 3) and np.allclose(a @ a.T, np.eye(3), atol=1e-9)


def _small_rotation(rng: np.random.Generator) -> np.ndarray:
    from onboard.geometry import rodrigues

    axis = rng.normal(size=3)
    return rodrigues(axis / np.linalg.norm(axis), float(rng.normal()) * 0.01)


def _perturb(args: tuple, rng: np.random.Generator) -> tuple:
    out = []
    for a in args:
        if isinstance(a, float) and math.isfinite(a):
            a = a * (1.0 + 0.01 * float(rng.normal()))
        elif isinstance(a, np.ndarray) and a.dtype == np.float64 and a.size <= 16:
            if _is_rotation(a):
                a = _small_rotation(rng) @ a
            elif a.shape == (4,) and abs(np.linalg.norm(a) - 1.0) < 1e-9:
                a = a * (1.0 + 0.01 * rng.normal(size=4))
                a = a / np.linalg.norm(a)
            elif np.isfinite(a).all():
                a = a * (1.0 + 0.01 * rng.normal(size=a.shape))
        out.append(a)
    return tuple(out)


# the arguments of these kernels are times, indices or a buffer's rows that must stay as they
# were (a perturbed time falls outside its buffer interval): recorded values only
_UNPERTURBED = {
    "onboard.estimation.dkf_kernels._fuse_latest",
    "onboard.estimation.dkf_kernels._replay",
    "onboard.estimation.dkf_kernels._predict",
    "onboard.estimation.dkf_kernels._view",
    "onboard.estimation.dkf_kernels._covariance",
    "onboard.estimation.dkf_kernels._bisect_right",
    "groundstation.sim.estimate.advance_errors",
    "groundstation.sim.estimate.delay_push",
    "groundstation.sim.estimate.estimate_of",
    "groundstation.sim.estimate.hand_off",
    "groundstation.sim.physics.physics_steps",
    "groundstation.sim.physics.gyro_mean",
}


# ---------------------------------------------------------------- the comparison
def _flat(x) -> np.ndarray:
    if isinstance(x, (tuple, list)):
        parts = [_flat(v) for v in x]
        return np.concatenate(parts) if parts else np.zeros(0)
    return np.atleast_1d(np.asarray(x, dtype=np.float64)).ravel()


def _agree(name: str, args: tuple) -> int:
    pairs = kernel_cases.CASES[name](args)
    if pairs is None:
        return 0
    for i, (got, want) in enumerate(pairs):
        np.testing.assert_allclose(
            _flat(got), _flat(want), rtol=RTOL, atol=ATOL, equal_nan=True,
            err_msg=f"{name}: output {i} differs from the reference",
        )  # fmt: skip
    return 1


@pytest.mark.parametrize("name", sorted(kernel_cases.CASES))
def test_kernel_agrees_with_its_reference(name, recorded):
    rng = np.random.default_rng(sum(map(ord, name)))  # seeded per kernel
    samples = list(recorded.kept.get(name, []))
    fresh = kernel_cases.FRESH.get(name)
    if fresh is not None:
        samples += [fresh(rng) for _ in range(SAMPLES)]
    assert samples, f"{name}: no recorded call and no fresh arguments"
    checked = 0
    for args in samples:
        checked += _agree(name, args)
        if name not in _UNPERTURBED:
            for _ in range(PERTURBED):
                checked += _agree(name, _perturb(args, rng))
    assert checked >= min(len(samples), 3), f"{name}: only {checked} calls in its domain"
