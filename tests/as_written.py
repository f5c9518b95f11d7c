"""The idealised simulator the older closed-loop regression tests were written for: the
state-estimate table as written (motion-capture grade, no per-sortie draw), a perfectly
calibrated pinhole camera at the centre of mass, the operator believing the true target size,
a projected blob with 1 px centre noise and its exact size, no detector faults. Those tests
check the control logic's behaviour against figures measured in those conditions; the
realistic defaults are tested in tests/test_realism.py and measured in docs/realism.md."""

from __future__ import annotations

import dataclasses

from groundstation.scenario import Scenario, load_scenario, with_changes


def as_written(s: Scenario) -> Scenario:
    """``s`` in the idealised conditions above (its own camera, mount and field of view)."""
    c = dataclasses.replace(
        s.camera,
        noise_px=1.0,
        centre_noise_k_px=0.0,
        size_noise_px=0.0,
        size_noise_rel=0.0,
        min_blob_px=0.0,
        false_probability=0.0,
        burst_probability=0.0,
        principal_offset_u_px=0.0,
        principal_offset_v_px=0.0,
        k1=0.0,
        k2=0.0,
        p1=0.0,
        p2=0.0,
        offset_m=(0.0, 0.0, 0.0),
    )
    b = dataclasses.replace(
        s.belief,
        target_diameter_m=s.target.diameter_m,
        camera_hfov_deg=c.hfov_deg,
        camera_mount_pitch_deg=c.mount_pitch_deg,
        camera_mount_roll_deg=c.mount_roll_deg,
        camera_k1=0.0,
        camera_k2=0.0,
        camera_offset_m=(0.0, 0.0, 0.0),
    )
    e = dataclasses.replace(s.estimate, profile="table")
    return with_changes(s, camera=c, belief=b, estimate=e)


def load_as_written(name) -> Scenario:
    """:func:`load_scenario` then :func:`as_written`."""
    return as_written(load_scenario(name))
