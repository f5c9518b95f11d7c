"""JSON encoders of the fast channels, from plain numbers: run where the file is written (the
recording process, or this one), so a sortie's thread only gathers the numbers.

Each encoder is a pure function of floats, strings and tuples; ``ENCODERS`` indexes them for
the hand-over. Non-finite numbers and missing values become ``null``.
"""

from __future__ import annotations

import math

_POSE = (
    '{"timestamp":{"sec":%d,"nsec":%d},"frame_id":"world","pose":{"position":'
    '{"x":%.4f,"y":%.4f,"z":%.4f},"orientation":{"x":%.6f,"y":%.6f,"z":%.6f,"w":%.6f}}}'
)
_TF = (
    '{"transforms":[{"timestamp":{"sec":%d,"nsec":%d},"parent_frame_id":"world",'
    '"child_frame_id":"body","translation":{"x":%.4f,"y":%.4f,"z":%.4f},'
    '"rotation":{"x":%.6f,"y":%.6f,"z":%.6f,"w":%.6f}},%s]}'
)
_CONTROL = (
    '{"t_s":%.6f,"mode":"%s","law":"%s","los_elev_rad":%s,"los_azim_rad":%s,'
    '"vel_elev_rad":%s,"vel_azim_rad":%s,"accel_desired_m_s2":[%.4f,%.4f,%.4f],'
    '"accel_normal_desired_m_s2":%s,"accel_normal_m_s2":%s,'
    '"body_rates_cmd_rad_s":[%.5f,%.5f,%.5f],"thrust_cmd":%.5f,'
    '"yaw_rate_cmd_rad_s":%s,"e_px":%s,"e_rate_px_s":%s,"speed_m_s":%s,'
    '"range_m":%s,"vel_m_s":%s,"e_raw_px":%s,"raw_capture_t_s":%s,"speed_cap_m_s":%s}'
)
_DKF = (
    '{"t_s":%.6f,"state":%s,"cov_diag":%s,"acquired":%s,"lost":%s,"time_since_detection_s":%s,'
    '"target_diameter_m":%s,"target_diameter_std_m":%s,"camera_offset_s":%s,'
    '"camera_offset_std_s":%s,"target_accel_m_s2":%s,"model_probs":%s,'
    '"target_turn_rate_rad_s":%s}'
)


def js(x: float | None) -> str:
    """A number as JSON (null when missing or not finite)."""
    return "null" if x is None or not math.isfinite(x) else "%.6g" % x


def js2(pair) -> str:
    return "null" if pair is None else "[%.3f,%.3f]" % (pair[0], pair[1])


def _js3(v) -> str:
    return (
        "null"
        if v is None or not math.isfinite(v[0] + v[1] + v[2])
        else ("[%.4f,%.4f,%.4f]" % (v[0], v[1], v[2]))
    )


def _js4(v) -> str:
    return "null" if v is None else "[%.4f,%.4f,%.4f,%.4f]" % tuple(v)


def pose(sec: int, nsec: int, x, y, z, qx, qy, qz, qw) -> bytes:
    """foxglove.PoseInFrame in the world frame."""
    return (_POSE % (sec, nsec, x, y, z, qx, qy, qz, qw)).encode()


def tf(sec: int, nsec: int, x, y, z, qx, qy, qz, qw, camera_tf: str) -> bytes:
    """foxglove.FrameTransforms: world -> body, and the fixed body -> camera given as JSON."""
    return (_TF % (sec, nsec, x, y, z, qx, qy, qz, qw, camera_tf)).encode()


def control(
    t_s, mode, law, q_y, q_z, s_y, s_z, a, an_des, an, w, thrust, yaw_rate, e, e_rate, speed,
    range_m, vel, e_raw, raw_t, speed_cap,
) -> bytes:  # fmt: skip
    """peregrine.Control (``a``, ``w`` and ``vel`` are 3-tuples, ``e``, ``e_rate`` and ``e_raw``
    pairs or None; ``speed_cap`` inf or NaN: none)."""
    return (
        _CONTROL
        % (
            t_s, mode, law, js(q_y), js(q_z), js(s_y), js(s_z), a[0], a[1], a[2], js(an_des),
            js(an), w[0], w[1], w[2], thrust, js(yaw_rate), js2(e), js2(e_rate),
            "null" if speed is None or not math.isfinite(speed) else "%.4f" % speed,
            js(range_m), _js3(vel), js2(e_raw), "null" if raw_t is None else "%.6f" % raw_t,
            js(speed_cap),
        )
    ).encode()  # fmt: skip


def dkf(
    t_s,
    state,
    cov,
    acquired: bool,
    lost: bool,
    since,
    self_cal=None,
    accel=None,
    probs=None,
    turn_rate=None,
) -> bytes:
    """peregrine.Dkf (``state`` and ``cov`` 4-tuples or None, ``self_cal`` a
    :class:`~onboard.estimation.self_calibration.SelfCalEstimate` or None, ``accel`` and
    ``probs`` the IMM's 3-tuples or None, ``turn_rate`` its CT turn rate, rad/s, or None)."""
    c = self_cal
    return (
        _DKF
        % (
            t_s,
            _js4(state),
            _js4(cov),
            "true" if acquired else "false",
            "true" if lost else "false",
            js(since),
            js(None if c is None else c.target_diameter_m),
            js(None if c is None else c.target_diameter_std_m),
            js(None if c is None else c.camera_offset_s),
            js(None if c is None else c.camera_offset_std_s),
            _js3(accel),
            _js3(probs),
            js(turn_rate),
        )
    ).encode()


ENCODERS = (pose, tf, control, dkf)
POSE, TF, CONTROL, DKF = range(4)
RAW = -1  # already encoded


def encode(enc: int, payload) -> bytes:
    return payload if enc == RAW else ENCODERS[enc](*payload)
