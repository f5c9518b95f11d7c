"""The idealised simulator the older closed-loop regression tests were written for: the
state-estimate table as written (motion-capture grade, no per-sortie draw), a perfectly
calibrated pinhole camera at the centre of mass, a projected blob with 1 px centre noise and
its exact size, no detector faults. Those tests check the control logic's behaviour against
figures measured in those conditions; the realistic defaults are tested in
tests/test_realism.py and measured in docs/realism.md. (Every shipped scenario's beliefs of
its target size, field of view and mount are its true ones already.)"""

from __future__ import annotations

from groundstation.scenario import Scenario, load_scenario, with_overrides

AS_WRITTEN = {  # --set keys
    "estimate.profile": "table",
    "camera.noise_px": 1.0,
    "camera.centre_noise_k_px": 0.0,
    "camera.size_noise_px": 0.0,
    "camera.size_noise_rel": 0.0,
    "camera.min_blob_px": 0.0,
    "camera.false_probability": 0.0,
    "camera.burst_probability": 0.0,
    "camera.principal_offset_u_px": 0.0,
    "camera.principal_offset_v_px": 0.0,
    "camera.k1": 0.0,
    "camera.k2": 0.0,
    "camera.p1": 0.0,
    "camera.p2": 0.0,
    "camera.offset_m": [0.0, 0.0, 0.0],
    "belief.camera_k1": 0.0,
    "belief.camera_k2": 0.0,
    "belief.camera_offset_m": [0.0, 0.0, 0.0],
    "belief.target_accel_noise_m_s2": 1.0,  # the DKF tuned for a motion-capture estimate
}


def as_written(s: Scenario) -> Scenario:
    """``s`` in the idealised conditions above."""
    return with_overrides(s, AS_WRITTEN)


def load_as_written(name) -> Scenario:
    """:func:`load_scenario` then :func:`as_written`."""
    return as_written(load_scenario(name))


def set_args(overrides: dict) -> list[str]:
    """``overrides`` as the command line's ``--set KEY=VALUE`` arguments."""
    out = []
    for k, v in overrides.items():
        value = f'"{v}"' if isinstance(v, str) else str(v).lower() if isinstance(v, bool) else v
        out += ["--set", f"{k}={value}"]
    return out
