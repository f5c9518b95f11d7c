"""Pinhole model of the strapdown camera: intrinsics, mount, projection and the rotational
columns of the interaction matrix (paper eq. 4)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .geometry import camera_mount_rotation
from .jit import kernel


@dataclass(frozen=True)
class CameraModel:
    width_px: int = 640
    height_px: int = 480
    hfov_deg: float = 90.0
    mount_pitch_deg: float = 0.0  # optical axis raised above body x
    mount_roll_deg: float = 0.0  # about the optical axis; 90 = portrait
    f_px: float = field(init=False)
    cu_px: float = field(init=False)
    cv_px: float = field(init=False)
    R_BC: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.width_px <= 0 or self.height_px <= 0:
            raise ValueError("camera size must be positive")
        if not 1.0 <= self.hfov_deg <= 170.0:
            raise ValueError(f"hfov_deg = {self.hfov_deg} must be in [1, 170]")
        object.__setattr__(
            self, "f_px", (self.width_px / 2.0) / math.tan(math.radians(self.hfov_deg) / 2.0)
        )
        object.__setattr__(self, "cu_px", self.width_px / 2.0)
        object.__setattr__(self, "cv_px", self.height_px / 2.0)
        R = camera_mount_rotation(self.mount_pitch_deg, self.mount_roll_deg)
        R.setflags(write=False)
        object.__setattr__(self, "R_BC", R)
        roll = math.radians(self.mount_roll_deg)
        object.__setattr__(self, "_roll_cos_sin", (math.cos(roll), math.sin(roll)))

    @property
    def vfov_deg(self) -> float:
        return math.degrees(2.0 * math.atan((self.height_px / 2.0) / self.f_px))

    def error_px(self, u_px: float, v_px: float) -> tuple[float, float]:
        """Image error e = (u - c_u, v - c_v) in pixels (paper eq. 3)."""
        return u_px - self.cu_px, v_px - self.cv_px

    def project(self, p_cam_m: np.ndarray) -> tuple[float, float] | None:
        """Pixel (u, v) of a camera-frame point, or None behind the camera (:func:`pixel_of`)."""
        x, y, z = (float(c) for c in p_cam_m)
        ahead, u, v = pixel_of(x, y, z, self.f_px, self.cu_px, self.cv_px)
        return (u, v) if ahead else None

    def upright(self, x: float, y: float) -> tuple[float, float]:
        """An image-plane vector (error or its rate) as an upright camera (no mount roll) would
        see it: x along the body's lateral axis, y along its vertical. The FOV-holding yaw
        loop needs this for a portrait-mounted camera."""
        c, s = self._roll_cos_sin
        return c * x - s * y, s * x + c * y

    def in_image(self, u_px: float, v_px: float, margin_px: float = 0.0) -> bool:
        return (
            -margin_px <= u_px < self.width_px + margin_px
            and -margin_px <= v_px < self.height_px + margin_px
        )


@kernel("UniTuple(float64, 3)(float64, float64, float64, float64, float64, float64)")
def pixel_of(
    x: float, y: float, z: float, f_px: float, cu_px: float, cv_px: float
) -> tuple[float, float, float]:
    """The pinhole projection of the camera-frame point (x, y, z) (m), compiled: (1, u, v)
    (px), or (0, nan, nan) behind the camera (z <= 1 um)."""
    if z <= 1e-6:
        return 0.0, math.nan, math.nan
    return 1.0, cu_px + f_px * x / z, cv_px + f_px * y / z


def rotational_flow(ex_n: float, ey_n: float, omega_cam_rad_s: np.ndarray) -> tuple[float, float]:
    """Rate of the normalised image point due to camera rotation alone: the angular-velocity
    columns of L_s (paper eq. 4) times omega (camera frame, rad/s). Returns (dex_n, dey_n)/s."""
    wx, wy, wz = float(omega_cam_rad_s[0]), float(omega_cam_rad_s[1]), float(omega_cam_rad_s[2])
    dx = ex_n * ey_n * wx - (1.0 + ex_n * ex_n) * wy + ey_n * wz
    dy = (1.0 + ey_n * ey_n) * wx - ex_n * ey_n * wy - ex_n * wz
    return dx, dy
