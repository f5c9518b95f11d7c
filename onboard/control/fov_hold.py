"""FOV-holding yaw-rate controller (paper eq. 13, sign per DESIGN.md §3 step 8)."""

from __future__ import annotations

from ..gains import Gains


def yaw_rate_command(e_x_px: float, e_x_rate_px_s: float, gains: Gains) -> float:
    """r_d = -(k_p e_x + k_d de_x/dt) in rad/s about body +z (FLU).

    A target right of centre (e_x > 0) needs a clockwise turn seen from above, which is a
    negative rate about +z_B; hence the minus sign the paper leaves implicit.
    """
    return -(gains.k_p * e_x_px + gains.k_d * e_x_rate_px_s)
