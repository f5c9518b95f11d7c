"""PX4 parameters the onboard computer reads when the link comes up, and what it says about
them: the settings that must agree with its own (``MPC_THR_HOVER`` with ``PRG_HOVER_THR``)
or bound what happens when it stops commanding (``COM_OF_LOSS_T``). Pure: values in, warnings
out; the runtime sends the reads and the warnings (``STATUSTEXT``)."""

from __future__ import annotations

import math

PX4_PARAMS_READ = ("COM_OF_LOSS_T", "MPC_THR_HOVER", "MPC_XY_VEL_MAX")
HOVER_TOLERANCE = 0.05  # normalised thrust
OFFBOARD_LOSS_ADVISED_S = (0.5, 1.0)  # README: "Wiring and PX4 parameters"


def check(name: str, value: float, hover_thr: float, v_max_m_s: float) -> tuple[str, str] | None:
    """(severity, text) about one PX4 parameter, or ``None`` when it is as it should be.
    Texts fit a STATUSTEXT (50 characters)."""
    if not math.isfinite(value):
        return ("warning", f"PX4 {name} is not a number")
    if name == "MPC_THR_HOVER" and abs(value - hover_thr) > HOVER_TOLERANCE:
        return ("warning", f"PX4 MPC_THR_HOVER {value:.2f} != PRG_HOVER_THR {hover_thr:.2f}")
    if name == "COM_OF_LOSS_T":
        lo, hi = OFFBOARD_LOSS_ADVISED_S
        if not lo <= value <= hi:
            return ("warning", f"PX4 COM_OF_LOSS_T {value:g} s: advised {lo:g}-{hi:g} s")
    if name == "MPC_XY_VEL_MAX" and value < v_max_m_s:
        return ("info", f"PX4 MPC_XY_VEL_MAX {value:g} < PRG_V_MAX {v_max_m_s:g} m/s")
    return None
