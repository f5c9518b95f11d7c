"""Model of the strapdown camera: intrinsics (focal length from the field of view, principal
point, Brown-Conrady lens distortion), mount, projection and the rotational columns of the
interaction matrix (paper eq. 4).

The simulator holds a true model of its camera; the loop holds the operator's calibration of
it, which is never the same: the loop undistorts each detection with the calibration it
believes (:meth:`CameraModel.undistort_px`) and works in the ideal pinhole image after that."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .datatypes import Detection
from .geometry import camera_mount_rotation
from .jit import kernel


@dataclass(frozen=True)
class CameraModel:
    width_px: int = 640
    height_px: int = 480
    hfov_deg: float = 90.0
    mount_pitch_deg: float = 0.0  # optical axis raised above body x
    mount_roll_deg: float = 0.0  # about the optical axis; 90 = portrait
    principal_offset_px: tuple[float, float] = (0.0, 0.0)  # principal point from the centre
    # Brown-Conrady (k1, k2, p1, p2) on normalised coordinates, as OpenCV's distCoeffs[:4]
    distortion: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    offset_b_m: tuple[float, float, float] = (0.0, 0.0, 0.0)  # from the centre of mass, FLU
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
        for name, n in (("principal_offset_px", 2), ("distortion", 4), ("offset_b_m", 3)):
            value = tuple(float(c) for c in getattr(self, name))
            if len(value) != n or not all(math.isfinite(c) for c in value):
                raise ValueError(f"{name} must be {n} finite numbers, got {value!r}")
            object.__setattr__(self, name, value)
        du, dv = self.principal_offset_px
        object.__setattr__(self, "cu_px", self.width_px / 2.0 + du)
        object.__setattr__(self, "cv_px", self.height_px / 2.0 + dv)
        R = camera_mount_rotation(self.mount_pitch_deg, self.mount_roll_deg)
        R.setflags(write=False)
        object.__setattr__(self, "R_BC", R)
        roll = math.radians(self.mount_roll_deg)
        object.__setattr__(self, "_roll_cos_sin", (math.cos(roll), math.sin(roll)))

    @property
    def vfov_deg(self) -> float:
        return math.degrees(2.0 * math.atan((self.height_px / 2.0) / self.f_px))

    @property
    def distorted(self) -> bool:
        return any(c != 0.0 for c in self.distortion)

    def distort_px(self, u_px: float, v_px: float) -> tuple[float, float]:
        """The pixel at which the lens images the ideal (pinhole) pixel (u, v)
        (:func:`distort_normalised`)."""
        if not self.distorted:
            return u_px, v_px
        f = self.f_px
        xd, yd = distort_normalised(
            (u_px - self.cu_px) / f, (v_px - self.cv_px) / f, *self.distortion
        )
        return self.cu_px + f * xd, self.cv_px + f * yd

    def disc_through_lens(
        self, u_px: float, v_px: float, r_px: float
    ) -> tuple[float, float, float]:
        """A small disc of the ideal image (centre, radius; px) as the lens images it: its
        centre distorted, its radius scaled by the lens's local magnification (the mean
        distance of the four distorted points at +-r along u and v from the centre)."""
        f = self.f_px
        xn, yn = (u_px - self.cu_px) / f, (v_px - self.cv_px) / f
        if not self.distorted or not xn * xn + yn * yn <= DISTORTION_MAX_R2:
            return u_px, v_px, r_px  # beyond the lens's calibrated field: out of the frame
        cu, cv = self.distort_px(u_px, v_px)
        m = 0.0
        for du, dv in ((r_px, 0.0), (-r_px, 0.0), (0.0, r_px), (0.0, -r_px)):
            a, b = self.distort_px(u_px + du, v_px + dv)
            m += math.hypot(a - cu, b - cv)
        return cu, cv, 0.25 * m

    def undistort_px(self, u_px: float, v_px: float) -> tuple[float, float]:
        """The ideal (pinhole) pixel of the lens's pixel (u, v) (:func:`undistort_normalised`,
        OpenCV's ``undistortPoints`` with ``P`` the pinhole matrix)."""
        if not self.distorted:
            return u_px, v_px
        f = self.f_px
        xn, yn = undistort_normalised(
            (u_px - self.cu_px) / f, (v_px - self.cv_px) / f, *self.distortion
        )
        return self.cu_px + f * xn, self.cv_px + f * yn

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

    @property
    def fov_edges_rad(self) -> tuple[float, float]:
        """The image's top and bottom edges above body x (rad; upright: a portrait camera's
        long side)."""
        roll = math.radians(self.mount_roll_deg)
        half_v = math.atan(
            (abs(math.cos(roll)) * self.height_px + abs(math.sin(roll)) * self.width_px)
            / (2.0 * self.f_px)
        )
        pitch = math.radians(self.mount_pitch_deg)
        return (pitch + half_v, pitch - half_v)

    def undistorted(self, detection: Detection) -> Detection:
        """``detection`` (the lens's pixels) with its centre undistorted (NaN where it cannot
        be: the DKF refuses it) and its area divided by the square of the lens's local
        magnification there (:meth:`disc_through_lens`): a barrel lens shrinks an off-axis
        blob (about 3 % at 20 deg with k1 = -0.1), which the DKF's size model would read as a
        longer range. A clipped blob's box is left as the detector saw it (the DKF reads it
        only to know whether the blob is whole)."""
        if not self.distorted:
            return detection
        d = detection
        try:
            u, v = self.undistort_px(float(d.center_px[0]), float(d.center_px[1]))
        except (TypeError, ValueError, IndexError):
            u = v = math.nan
        area = d.area_px
        try:
            a = float(area)
        except (TypeError, ValueError):
            a = math.nan
        if a > 0.0 and math.isfinite(a) and math.isfinite(u) and math.isfinite(v):
            r = math.sqrt(a / math.pi)
            m = self.disc_through_lens(u, v, r)[2] / r
            if m > 0.0:
                area = a / (m * m)
        return Detection(d.capture_time_s, (u, v), d.bbox_px, area, d.score)


@kernel("UniTuple(float64, 3)(float64, float64, float64, float64, float64, float64)")
def pixel_of(
    x: float, y: float, z: float, f_px: float, cu_px: float, cv_px: float
) -> tuple[float, float, float]:
    """The pinhole projection of the camera-frame point (x, y, z) (m), compiled: (1, u, v)
    (px), or (0, nan, nan) behind the camera (z <= 1 um)."""
    if z <= 1e-6:
        return 0.0, math.nan, math.nan
    return 1.0, cu_px + f_px * x / z, cv_px + f_px * y / z


def distort_normalised(
    x: float, y: float, k1: float, k2: float, p1: float, p2: float
) -> tuple[float, float]:
    """Brown-Conrady distortion of the normalised image point (x, y) (OpenCV's model with
    k3 = 0): radial 1 + k1 r^2 + k2 r^4 and tangential (p1, p2)."""
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * k2)
    return (
        x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
        y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
    )


# the polynomial describes the lens only within the calibrated field (a 90 deg, 4:3 frame's
# corners are at r^2 = 1.56): beyond r^2 = 4 (63 deg off axis) a disc is drawn undistorted
DISTORTION_MAX_R2 = 4.0
UNDISTORT_ITERATIONS = 20  # fixed-point steps: 1e-9 px at a 90 deg frame's corner


def undistort_normalised(
    xd: float, yd: float, k1: float, k2: float, p1: float, p2: float
) -> tuple[float, float]:
    """The inverse of :func:`distort_normalised` by fixed-point iteration, as OpenCV's
    ``undistortPoints``: x = (x_d - tangential(x)) / radial(x)."""
    x, y = xd, yd
    for _ in range(UNDISTORT_ITERATIONS):
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * k2)
        dx = 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
        dy = p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
        x, y = (xd - dx) / radial, (yd - dy) / radial
    return x, y


def rotational_flow(ex_n: float, ey_n: float, omega_cam_rad_s: np.ndarray) -> tuple[float, float]:
    """Rate of the normalised image point due to camera rotation alone: the angular-velocity
    columns of L_s (paper eq. 4) times omega (camera frame, rad/s). Returns (dex_n, dey_n)/s."""
    wx, wy, wz = float(omega_cam_rad_s[0]), float(omega_cam_rad_s[1]), float(omega_cam_rad_s[2])
    dx = ex_n * ey_n * wx - (1.0 + ex_n * ex_n) * wy + ey_n * wz
    dy = (1.0 + ey_n * ey_n) * wx - ex_n * ey_n * wy - ex_n * wz
    return dx, dy
