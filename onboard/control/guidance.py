"""Guidance: line of sight from the image, LOS/velocity angles and the guidance laws that
turn them into a desired acceleration (paper eqs. 5-9, 14, 17; DESIGN.md §3 steps 2-7, §5).

All vectors are world ENU. A law is a function ``(GuidanceInput, Gains) -> GuidanceOutput``.

The law's pieces live in :mod:`.los` (eqs. 5-8), :mod:`.png` (eqs. 8-9, 14, 17 and the FOV
terms), :mod:`.apn` (augmented PN) and :mod:`.baselines` (PG, IBVS); this module names the
laws and re-exports the pieces.
"""

from __future__ import annotations

from collections.abc import Callable

from ..enums import GuidanceLaw as Law
from ..gains import Gains
from .apn import apn_law
from .baselines import ibvs_law, pursuit_law, track_velocity_direction
from .guidance_io import GuidanceInput, GuidanceOutput, _hover_start
from .los import (
    _f3,
    _max,
    _min,
    angles_floats,
    direction_angles,
    direction_from_angles,
    hypot2,
    line_of_sight,
    los_change,
    los_floats,
    los_terms,
    normal_component,
    normal_floats,
    saturate3,
    saturate_norm,
    smooth_los_change,
)
from .png import (
    accel_toward_velocity,
    believed_drag_floats,
    drag_feedforward_floats,
    edge_margin_floats,
    edge_margin_rad,
    fov_guard,
    fov_guard_floats,
    midcourse_floats,
    midcourse_weight,
    min_pitch_rad,
    png_command,
    png_floats,
    png_law,
    pursuit_floats,
    pursuit_weight,
    ramped_speed,
    ramped_speed_floats,
    zem_floats,
    zem_nulling_accel,
)

__all__ = [
    "GUIDANCE_LAWS",
    "GuidanceInput",
    "GuidanceLaw",
    "GuidanceOutput",
    "_f3",
    "_hover_start",
    "_max",
    "_min",
    "accel_toward_velocity",
    "angles_floats",
    "believed_drag_floats",
    "direction_angles",
    "direction_from_angles",
    "drag_feedforward_floats",
    "edge_margin_floats",
    "edge_margin_rad",
    "fov_guard",
    "fov_guard_floats",
    "hypot2",
    "ibvs_law",
    "line_of_sight",
    "los_change",
    "los_floats",
    "los_terms",
    "midcourse_floats",
    "midcourse_weight",
    "min_pitch_rad",
    "normal_component",
    "normal_floats",
    "png_command",
    "png_floats",
    "png_law",
    "pursuit_floats",
    "pursuit_law",
    "pursuit_weight",
    "ramped_speed",
    "ramped_speed_floats",
    "saturate3",
    "saturate_norm",
    "smooth_los_change",
    "track_velocity_direction",
    "zem_floats",
    "zem_nulling_accel",
]  # fmt: skip

GuidanceLaw = Callable[[GuidanceInput, Gains], GuidanceOutput]

GUIDANCE_LAWS: dict[str, GuidanceLaw] = {
    Law.PNG.value: png_law,
    Law.PG.value: pursuit_law,
    Law.IBVS.value: ibvs_law,
    Law.APN.value: apn_law,
}
assert set(GUIDANCE_LAWS) == {m.value for m in Law}
