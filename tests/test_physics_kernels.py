"""Each physics kernel (groundstation/sim/physics.py, target_kernels.py) compiled computes
bit for bit what its own Python source (``k.py_func``) computes, on seeded random inputs:
states, parameters, every target motion, both wind models, the command clamp (NaN included)
and whole stretches of a sortie's physics from real scenarios."""

from __future__ import annotations

import numpy as np
import pytest

from groundstation.scenario import load_scenario
from groundstation.sim import physics as ph
from groundstation.sim import target_kernels as tk
from groundstation.sim.simulation import Simulation
from groundstation.sim.wind import turbulence_modes
from onboard import jit

pytestmark = pytest.mark.skipif(not jit.ENABLED, reason="PEREGRINE_JIT=0: nothing compiled")

CASES = 200


def same(a, b) -> bool:
    """Bit for bit (NaNs and the sign of zero included)."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    return a.shape == b.shape and a.tobytes() == b.tobytes()


def both(k, arrays: tuple, *args):
    """Run the compiled kernel and its Python source on copies of ``arrays`` (mutated in
    place) followed by ``args``; return (compiled result, arrays), (Python result, arrays)."""
    out = []
    for f in (k, k.py_func):
        copies = tuple(a.copy() for a in arrays)
        out.append((f(*copies, *args), copies))
    return out


def test_vehicle_step():
    rng = np.random.default_rng(1)
    for i in range(CASES):
        x = rng.normal(0.0, 3.0, ph.X_SIZE)
        q = rng.normal(size=4)
        x[ph.X_Q : ph.X_Q + 4] = q / np.linalg.norm(q)
        x[ph.X_THRUST] = x[ph.X_CMD_THRUST] = abs(x[ph.X_THRUST]) * 5.0
        if i % 10 == 0:
            x[ph.X_W : ph.X_W + 3] = x[ph.X_CMD_W : ph.X_CMD_W + 3] = 0.0  # no rotation
        lag = np.array(
            [*rng.uniform(0, 1, 2), rng.uniform(0, 2), 0.6, *rng.uniform(0, [0.02, 0.05, 0.2])]
        )
        (r1, a1), (r2, a2) = both(ph.vehicle_step, (x, lag), 1.0 / 600.0, *rng.normal(size=3))
        assert same(r1, r2) and same(a1[0], a2[0]), i


def test_vehicle_command_clamps_like_python():
    rng = np.random.default_rng(2)
    for i in range(CASES):
        c = rng.normal(0.0, 6.0, 4)
        if i % 7 == 0:
            c[i % 4] = np.nan
        t = float(rng.uniform(-0.5, 1.5)) if i % 9 else float("nan")
        (_, a1), (_, a2) = both(ph.vehicle_command, (np.zeros(ph.X_SIZE),), 3.5, 29.4, *c[:3], t)
        assert same(a1[0], a2[0]), i


@pytest.mark.parametrize("kind", range(len(tk.MOTIONS)), ids=tk.MOTIONS)
def test_target_step_every_motion(kind):
    rng = np.random.default_rng(10 + kind)
    for i in range(CASES // 2):
        c = rng.normal(0.0, 3.0, tk.T_SIZE)
        c[tk.T_MAX_SPEED] = abs(c[tk.T_MAX_SPEED]) + 0.5
        c[tk.T_DRAG_K], c[tk.T_MASS] = 0.01, abs(c[tk.T_MASS]) * 0.01 + 0.005
        c[tk.T_ROPE] = abs(c[tk.T_ROPE]) + 0.1
        c[tk.T_TWO] = 2.0
        c[tk.T_DIA], c[tk.T_AREA] = 0.16, 0.02
        times = np.cumsum(rng.uniform(0.1, 1.0, 6))
        track = np.column_stack([times, rng.normal(0.0, 5.0, (6, 3))])
        x = rng.normal(0.0, 2.0, tk.TX_SIZE)
        t = float(rng.uniform(-1.0, 8.0))
        wind = rng.normal(size=3)
        interceptor = x[:3] + rng.normal(0.0, 8.0, 3)
        out = []
        for f in (tk.target_step, tk.target_step.py_func):
            xc = x.copy()
            f(kind, c, track, xc, t, 1.0 / 600.0, *wind, *interceptor)
            out.append(xc)
        assert same(out[0], out[1]), (kind, i)


def test_jet_factor_and_wind_at():
    rng = np.random.default_rng(3)
    for i in range(CASES):
        m, s, p = rng.normal(0.0, 3.0, 3), rng.normal(0.0, 2.0, 3), rng.normal(0.0, 4.0, 3)
        dia = float(rng.uniform(0.1, 1.0))
        for on_axis in (False, True):
            args = (*m, *s, dia, *p, on_axis)
            assert same(ph.jet_factor(*args), ph.jet_factor.py_func(*args)), i
        c = np.zeros(ph.W_SIZE)
        c[ph.W_MEAN : ph.W_MEAN + 3], c[ph.W_SOURCE : ph.W_SOURCE + 3] = m, s
        c[ph.W_DIA], c[ph.W_JET], c[ph.W_REF] = dia, float(i % 2), rng.uniform(0.2, 1.0)
        c[ph.W_SIGMA : ph.W_SIGMA + 3] = rng.uniform(0.0, 1.0, 3)
        c[ph.W_TIME] = rng.uniform(0.0, 100.0)
        modes = turbulence_modes(rng, float(rng.uniform(0.1, 50.0)), int(rng.integers(1, 20)))
        c[ph.W_NMODES] = len(modes) if i % 3 else 0
        assert same(ph.wind_at(c, modes, *p), ph.wind_at.py_func(c, modes, *p)), i


def test_rotor_wash_at():
    rng = np.random.default_rng(4)
    for i in range(CASES):
        x = rng.normal(0.0, 3.0, ph.X_SIZE)
        q = rng.normal(size=4)
        x[ph.X_Q : ph.X_Q + 4] = q / np.linalg.norm(q)
        x[ph.X_THRUST] = abs(x[ph.X_THRUST]) * 5.0
        lag = rng.uniform(0.0, 1.0, ph.L_SIZE)
        args = (*rng.normal(size=3), *(x[0:3] + rng.normal(0.0, 2.0, 3)))
        assert same(ph.rotor_wash_at(x, lag, *args), ph.rotor_wash_at.py_func(x, lag, *args)), i


@pytest.mark.parametrize(
    "name", ["cv-top-to-bottom", "indoor-tethered-wind-4", "outdoor-escape", "outdoor-circle"]
)
def test_physics_steps_on_sortie_states(name):
    """Stretches of 1..20 steps from a real sortie's state, perturbed, with a command on its
    way: the compiled kernel and its Python source leave the same array and step count."""
    rng = np.random.default_rng(5)
    sim = Simulation(load_scenario(name), "png", 1, keep_records=False)
    for i in range(20):
        buf = sim._physics.copy()
        buf[ph.S_VX : ph.S_VX + 6] += rng.normal(0.0, 0.5, 6)
        buf[ph.S_CMD : ph.S_CMD + 5] = (i % 4, *rng.normal(0.0, 2.0, 3), rng.uniform(0, 1))
        n = int(rng.integers(1, 21))
        out = []
        for f in (ph.physics_steps, ph.physics_steps.py_func):
            b = buf.copy()
            out.append((f(i, n, b, sim.target.track, sim.wind.modes), b))
        assert out[0][0] == out[1][0] and same(out[0][1], out[1][1]), (name, i)
        sim.step_control_period()  # on along the sortie
        if sim.done:
            break


def test_closest_approach():
    rng = np.random.default_rng(6)
    for i in range(CASES):
        r = rng.normal(0.0, 2.0, 6)
        if i % 10 == 0:
            r[3:] = r[:3]  # no relative motion over the step
        assert same(ph.closest_approach(*r), ph.closest_approach.py_func(*r)), i


def test_a_recorded_track_with_a_repeated_stamp_flies_and_one_going_back_is_refused():
    from groundstation.scenario import TargetSpec
    from groundstation.sim.targets import TrackTarget

    spec = TargetSpec(motion="static", position_m=(0.0, 0.0, 10.0))
    # a log may hold two samples at one stamp: the first stands (no division by a zero span,
    # which compiled raised ZeroDivisionError and as Python gave NaN)
    tgt = TrackTarget(spec, [0.0, 1.0, 1.0], [(0, 0, 10), (1, 0, 10), (1, 0, 10)])
    assert tgt.track.shape == (2, 4)
    for t in (0.5, 1.0, 1.5):
        tgt.advance(t, 0.5, (0.0, 0.0, 0.0))
    assert tgt.p == pytest.approx([1.5, 0.0, 10.0]) and tgt.v == pytest.approx([1.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="before the previous"):
        TrackTarget(spec, [0.0, 1.0, 0.5], [(0, 0, 10)] * 3)
    with pytest.raises(ValueError, match="not a finite"):
        TrackTarget(spec, [0.0, 1.0], [(0, 0, 10), (float("nan"), 0, 10)])
    with pytest.raises(ValueError, match="at least two"):
        TrackTarget(spec, [1.0, 1.0], [(0, 0, 10), (0, 0, 10)])


def _pass_by(target_x_m: float, push_y_m_s: float) -> tuple[int, float, float]:
    """A vehicle at 10 m/s along x past a static target 0.3 m to its side, the wind pushing
    it sideways (no drag along x), flown for 0.6 s (the pass is at 0.5 s): the pass's code
    (0 before it), the miss (m) and the pass's time (s)."""
    from onboard.datatypes import GRAVITY_M_S2

    dt, mass = 0.01, 1.5
    b = np.zeros(ph.S_SIZE)
    x = b[ph.S_VX : ph.S_VX + ph.X_SIZE]
    x[0:3], x[3:6], x[6] = (0.0, 0.0, 10.0), (10.0, 0.0, 0.0), 1.0
    x[16] = x[20] = mass * GRAVITY_M_S2
    b[ph.S_LAG : ph.S_LAG + 4] = (1.0, 1.0, 0.5, mass)
    b[ph.S_TX : ph.S_TX + 3] = (target_x_m, 0.3, 10.0)
    b[ph.S_WC + ph.W_MEAN : ph.S_WC + ph.W_MEAN + 3] = (10.0, push_y_m_s, 0.0)
    cs = b[ph.S_CS : ph.S_CS + ph.C_SIZE]
    cs[ph.C_REL : ph.C_REL + 3] = b[ph.S_TX : ph.S_TX + 3] - x[0:3]
    cs[ph.C_MISS], cs[ph.C_HIT_R], cs[ph.C_TWO] = 1e9, 0.35, 2.0
    b[ph.S_CMD], b[ph.S_KIND], b[ph.S_DT] = -1.0, 0, dt
    taken = ph.physics_steps(0, 60, b, np.zeros((0, 4)), np.zeros((0, ph.M_SIZE)))
    assert taken == 60 and cs[ph.C_OUTCOME] == ph.OUTCOME_NONE  # the sortie goes on
    return int(cs[ph.C_PASS]), float(cs[ph.C_MISS]), float(cs[ph.C_PASS_TIME])


@pytest.mark.parametrize("push_y_m_s", [-20.0, 0.0, 20.0])
def test_every_pass_is_scored_even_at_a_step_boundary(push_y_m_s):
    # the target's position scanned over one 10 cm step: somewhere the closest point is the
    # boundary between two steps (the step before still closing at its end, the one after
    # opening from its start), where no step was "closing then opening" and 6-10 % of these
    # passes went unscored
    for tx in np.linspace(5.0, 5.1, 201):
        code, miss, pass_time_s = _pass_by(float(tx), push_y_m_s)
        assert code == (ph.OUTCOME_HIT if miss <= 0.35 else ph.OUTCOME_MISS), (tx, miss)
        assert 0.4 <= pass_time_s <= 0.6, (tx, pass_time_s)  # scored as the range opens
