"""Rotations and frame helpers (world ENU, body FLU, camera OpenCV).

Quaternions are (w, x, y, z) and rotate body vectors into the world frame.
"""

from __future__ import annotations

import math

import numpy as np

from .jit import kernel

E_Z = np.array([0.0, 0.0, 1.0])

# Camera (x right, y down, z optical axis) -> body (x forward, y left, z up), camera looking
# straight ahead: columns are the camera axes expressed in the body frame.
R_BC_FORWARD = np.array(
    [
        [0.0, 0.0, 1.0],
        [-1.0, 0.0, 0.0],
        [0.0, -1.0, 0.0],
    ]
)


@kernel("float64(float64)")
def wrap_pi(angle_rad: float) -> float:
    """Wrap an angle to (-pi, pi] (compiled; nan for a non-finite angle)."""
    a = (angle_rad + math.pi) % (2.0 * math.pi)  # numba has no math.fmod; the same result
    if a <= 0.0:
        a += 2.0 * math.pi
    return a - math.pi


def hat(v: np.ndarray) -> np.ndarray:
    """Skew-symmetric matrix [v]x such that hat(v) @ w == cross(v, w)."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def vex(m: np.ndarray) -> np.ndarray:
    """Inverse of :func:`hat` for a skew-symmetric matrix."""
    return np.array([m[2, 1], m[0, 2], m[1, 0]])


def as_quat(q_wxyz) -> np.ndarray:
    """A quaternion (w, x, y, z) as a writable float64 4-vector (the array itself when it is
    one), for the kernels, which do not check the length."""
    q = np.asarray(q_wxyz, dtype=np.float64)
    if q.shape != (4,):
        raise ValueError(f"a quaternion has 4 components, not shape {q.shape}")
    return q if q.flags.writeable else q.copy()  # the kernels' signatures take writable ones


def quat_to_rotmat(q_wxyz: np.ndarray) -> np.ndarray:
    """Rotation matrix of a unit quaternion (w, x, y, z) (:func:`rotmat_of_quat`)."""
    return rotmat_of_quat(as_quat(q_wxyz))


@kernel("float64[:, ::1](float64[:])")
def rotmat_of_quat(q: np.ndarray) -> np.ndarray:
    """:func:`quat_to_rotmat` of a float64 4-vector (compiled)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    R = np.empty((3, 3))
    R[0, 0], R[0, 1], R[0, 2] = 1.0 - 2.0 * (yy + zz), 2.0 * (xy - wz), 2.0 * (xz + wy)
    R[1, 0], R[1, 1], R[1, 2] = 2.0 * (xy + wz), 1.0 - 2.0 * (xx + zz), 2.0 * (yz - wx)
    R[2, 0], R[2, 1], R[2, 2] = 2.0 * (xz - wy), 2.0 * (yz + wx), 1.0 - 2.0 * (xx + yy)
    return R


@kernel("float64[:, ::1](float64[:, :], float64[:, :])")
def mat3_mul(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """A B for 3x3 matrices (compiled), each entry's sum in index order: numpy's product goes
    to BLAS, whose rounding (FMA or not) depends on the CPU, and the same seeds must fly the
    same sortie anywhere."""
    C = np.empty((3, 3))
    for i in range(3):
        a0, a1, a2 = A[i, 0], A[i, 1], A[i, 2]
        for j in range(3):
            C[i, j] = a0 * B[0, j] + a1 * B[1, j] + a2 * B[2, j]
    return C


@kernel("float64[:, ::1](float64[:], float64[:, :])")
def camera_attitude(q_wxyz: np.ndarray, R_BC: np.ndarray) -> np.ndarray:
    """R_WC = R_WB R_BC of the body attitude quaternion (w, x, y, z) and the camera mount
    ``R_BC`` (compiled: :func:`rotmat_of_quat`, :func:`mat3_mul`)."""
    return mat3_mul(rotmat_of_quat(q_wxyz), R_BC)


@kernel("Tuple((float64[:, ::1], float64[:, ::1]))(float64[:], float64[:, :])")
def body_and_camera_attitude(q_wxyz: np.ndarray, R_BC: np.ndarray):
    """(R_WB, R_WC = R_WB R_BC) of the body attitude quaternion (w, x, y, z) and the camera
    mount ``R_BC`` (compiled: :func:`rotmat_of_quat`, :func:`mat3_mul`)."""
    R_WB = rotmat_of_quat(q_wxyz)
    return R_WB, mat3_mul(R_WB, R_BC)


def _floats(v) -> list:
    """A short vector as Python floats (arithmetic on numpy scalars costs several times more
    and gives the same IEEE results)."""
    return v.tolist() if isinstance(v, np.ndarray) else [float(c) for c in v]


_F4 = "UniTuple(float64, 4)"


@kernel(f"{_F4}(float64, float64, float64, float64, float64, float64, float64, float64)")
def quat_mul4(
    aw: float, ax: float, ay: float, az: float, bw: float, bx: float, by: float, bz: float
) -> tuple[float, float, float, float]:
    """Hamilton product a b of quaternions (w, x, y, z), component by component (a kernel
    other kernels call; :func:`quat_mul_floats` takes sequences)."""
    return (
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    )


def quat_mul_floats(a, b) -> tuple[float, float, float, float]:
    """Hamilton product a b of quaternions (w, x, y, z) given as sequences of floats, as a
    tuple of floats (:func:`quat_mul` without the arrays)."""
    return quat_mul4(*a, *b)


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a b of quaternions (w, x, y, z)."""
    return np.array(quat_mul_floats(_floats(a), _floats(b)))


@kernel(f"{_F4}(float64, float64, float64)")
def quat_exp3(x: float, y: float, z: float) -> tuple[float, float, float, float]:
    """Unit quaternion (w, x, y, z) of the rotation vector (x, y, z) (rad), a kernel other
    kernels call (:func:`quat_exp_floats` takes a sequence)."""
    ang = math.sqrt(x * x + y * y + z * z)
    if ang < 1e-12:
        return (1.0, 0.5 * x, 0.5 * y, 0.5 * z)
    s = math.sin(0.5 * ang) / ang
    return (math.cos(0.5 * ang), s * x, s * y, s * z)


def quat_exp_floats(rotvec_rad) -> tuple[float, float, float, float]:
    """Unit quaternion (w, x, y, z) of a rotation vector (rad, a sequence of floats), as a
    tuple of floats (:func:`quat_exp` without the arrays)."""
    return quat_exp3(*rotvec_rad)


def quat_exp(rotvec_rad: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a rotation vector (rad)."""
    return np.array(quat_exp_floats(_floats(rotvec_rad)))


def propagate_attitude(q_wxyz: np.ndarray, rates_flu_rad_s: np.ndarray, dt_s: float) -> np.ndarray:
    """The attitude ``dt_s`` later at constant body rates: q exp(omega dt) (body-frame
    rotation; exact for constant rates, renormalised). ``dt_s`` may be negative (back in
    time); ``dt_s = 0`` returns ``q_wxyz`` unchanged. In floats: the same operations in the
    same order as the array form (the norm's sum of squares in index order)."""
    if dt_s == 0.0:
        return np.asarray(q_wxyz, dtype=float)
    return np.array(propagated_quat(*_floats(q_wxyz), *_floats(rates_flu_rad_s), dt_s))


@kernel(f"{_F4}(float64, float64, float64, float64, float64, float64, float64, float64)")
def propagated_quat(
    q0: float, q1: float, q2: float, q3: float, r0: float, r1: float, r2: float, dt_s: float
) -> tuple[float, float, float, float]:
    """:func:`propagate_attitude` (``dt_s`` not zero) in floats: q exp(omega dt), the norm's
    sum of squares in index order."""
    e0, e1, e2, e3 = quat_exp3(r0 * dt_s, r1 * dt_s, r2 * dt_s)
    a0, a1, a2, a3 = quat_mul4(q0, q1, q2, q3, e0, e1, e2, e3)
    n = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2 + a3 * a3)
    return (a0 / n, a1 / n, a2 / n, a3 / n)


@kernel(
    "UniTuple(float64, 5)(float64, float64, float64, float64, float64, float64, float64,"
    " float64, float64, float64, float64)"
)
def carried_attitude(
    now_s: float,
    q0: float,
    q1: float,
    q2: float,
    q3: float,
    q_time_s: float,
    r0: float,
    r1: float,
    r2: float,
    max_dt_s: float,
    max_rate_rad_s: float,
) -> tuple[float, float, float, float, float]:
    """The attitude (w, x, y, z) sampled at ``q_time_s`` carried to ``now_s`` (s) at the body
    rates (r0, r1, r2) (rad/s FLU), by at most ``max_dt_s`` and not at all at rates beyond
    ``max_rate_rad_s`` (or not finite), and the time it is of then
    (``fc_state.vehicle_state_at``; the simulator's hand-off calls it too)."""
    dt = min(max(now_s - q_time_s, 0.0), max_dt_s)
    if not math.sqrt(r0 * r0 + r1 * r1 + r2 * r2) <= max_rate_rad_s:  # NaN fails too
        return q0, q1, q2, q3, q_time_s
    if dt != 0.0:
        q0, q1, q2, q3 = propagated_quat(q0, q1, q2, q3, r0, r1, r2, dt)
    return q0, q1, q2, q3, q_time_s + dt


def propagate_rotation(R_WB: np.ndarray, rates_flu_rad_s: np.ndarray, lag_s: float) -> np.ndarray:
    """The attitude ``lag_s`` seconds after ``R_WB`` at the body rates ``rates_flu_rad_s``
    (held): R_WB exp([w lag]x), :func:`propagate_attitude` on a rotation matrix; non-finite
    rates leave it unchanged. The attitude estimate arrives late (EKF2's output predictor
    plus the link, about 10 ms) while the image estimate is predicted to the tick: at the
    endgame's body rates of a few rad/s that lag is a LOS error of tens of mrad."""
    w = np.asarray(rates_flu_rad_s, dtype=float)
    n = math.sqrt(float(w @ w))
    if not (n > 0.0 and math.isfinite(n)):
        return R_WB
    return R_WB @ rodrigues(w / n, n * lag_s)


def rotmat_to_quat(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) with w >= 0 of a rotation matrix (Shepperd's method)."""
    tr = R[0, 0] + R[1, 1] + R[2, 2]
    if tr > 0.0:
        s = 2.0 * math.sqrt(tr + 1.0)
        q = [0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s]
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = 2.0 * math.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2])
        q = [(R[2, 1] - R[1, 2]) / s, 0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s]
    elif R[1, 1] > R[2, 2]:
        s = 2.0 * math.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2])
        q = [(R[0, 2] - R[2, 0]) / s, (R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s]
    else:
        s = 2.0 * math.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1])
        q = [(R[1, 0] - R[0, 1]) / s, (R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s]
    qa = np.array(q)
    qa /= np.linalg.norm(qa)
    return -qa if qa[0] < 0.0 else qa


def rot_x(angle_rad: float) -> np.ndarray:
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(angle_rad: float) -> np.ndarray:
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(angle_rad: float) -> np.ndarray:
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def attitude_from_yaw_pitch_roll(yaw_rad: float, pitch_rad: float = 0.0, roll_rad: float = 0.0):
    """Body(FLU)->world(ENU) rotation from Z-Y-X angles.

    yaw is the heading of body x measured from world +x toward +y (90 deg faces +y / north);
    positive pitch raises the nose (FLU: a negative rotation about body y).
    """
    return rot_z(yaw_rad) @ rot_y(-pitch_rad) @ rot_x(roll_rad)


_I3 = np.eye(3)
_I3.flags.writeable = False


def rodrigues(axis_unit: np.ndarray, angle_rad: float) -> np.ndarray:
    """R = I + sin(phi) [r]x + (1 - cos(phi)) [r]x^2 (paper eq. 19)."""
    K = hat(axis_unit)
    return _I3 + math.sin(angle_rad) * K + (1.0 - math.cos(angle_rad)) * (K @ K)


@kernel("float64(float64[:, :], float64[:, :], float64, float64, float64, float64)")
def attitude_jump_rad(
    R0: np.ndarray, R1: np.ndarray, w0: float, w1: float, w2: float, dt_s: float
) -> float:
    """How far (rad) attitude R1 is from attitude R0 turned by the body rates (w0, w1, w2)
    (rad/s FLU) for ``dt_s`` (s): |log(R0^T R1) - w dt|, the rotation vectors' difference (to
    first order in it; angles below pi). Compared with a threshold only: its rounding is not
    any flown number's."""
    m = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            m[i, j] = R0[0, i] * R1[0, j] + R0[1, i] * R1[1, j] + R0[2, i] * R1[2, j]
    x = 0.5 * (m[2, 1] - m[1, 2])
    y = 0.5 * (m[0, 2] - m[2, 0])
    z = 0.5 * (m[1, 0] - m[0, 1])
    s = math.sqrt(x * x + y * y + z * z)  # sin(angle)
    if s > 1e-12:
        k = math.atan2(s, 0.5 * (m[0, 0] + m[1, 1] + m[2, 2] - 1.0)) / s
        x, y, z = x * k, y * k, z * k
    ex, ey, ez = x - w0 * dt_s, y - w1 * dt_s, z - w2 * dt_s
    return math.sqrt(ex * ex + ey * ey + ez * ez)


def cross3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b for 3-vectors (np.cross is ~20x slower on tiny arrays)."""
    a0, a1, a2 = float(a[0]), float(a[1]), float(a[2])
    b0, b1, b2 = float(b[0]), float(b[1]), float(b[2])
    return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])


def rotation_between(a_unit: np.ndarray, b_unit: np.ndarray) -> np.ndarray:
    """Smallest rotation taking unit vector a onto unit vector b (the paper's R_tilt, eq. 19).

    Axis a x b, angle acos(a . b). For antiparallel vectors any perpendicular axis is used.
    """
    c = min(max(float(a_unit @ b_unit), -1.0), 1.0)
    axis = cross3(a_unit, b_unit)
    s = math.sqrt(float(axis @ axis))
    if s < 1e-9:
        if c > 0.0:
            return np.eye(3)
        perp = cross3(a_unit, np.array([1.0, 0.0, 0.0]))
        if float(perp @ perp) < 1e-12:
            perp = cross3(a_unit, np.array([0.0, 1.0, 0.0]))
        return rodrigues(perp / math.sqrt(float(perp @ perp)), math.pi)
    return rodrigues(axis / s, math.atan2(s, c))


def camera_mount_rotation(pitch_up_deg: float = 0.0, roll_deg: float = 0.0) -> np.ndarray:
    """R_BC for a strapdown camera pitched up by ``pitch_up_deg`` and rolled about its optical
    axis by ``roll_deg`` (90 deg = portrait, as in the paper's outdoor flights)."""
    return rot_y(-math.radians(pitch_up_deg)) @ R_BC_FORWARD @ rot_z(math.radians(roll_deg))
