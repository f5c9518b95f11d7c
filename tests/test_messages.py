"""One definition per controller message (onboard/messages.py): the MCAP schemas and the live
MAVLink telemetry's layout are derived from it, the encoders write exactly its fields, in its
order, and no second list of the link's fields is written anywhere in the product."""

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from groundstation.app.live_frames import live_frame, telemetry_from_values
from onboard import messages
from onboard.camera_model import CameraModel
from onboard.channels import encode as enc
from onboard.channels.schemas import SCHEMAS
from onboard.datatypes import ControlTelemetry, LoopMode, RateThrustCommand
from onboard.estimation.self_calibration import SelfCalEstimate
from onboard.gains import Gains
from onboard.link import telemetry as tm


def test_schemas_and_encoders_follow_the_one_definition():
    control = json.loads(
        enc.control(
            1.0, "tracking", "png", 0.1, 0.2, 0.3, 0.4, (1.0, 2.0, 3.0), 1.5, 1.2,
            (0.1, 0.2, 0.3), 0.5, 0.05, (3.0, -2.0), (1.0, 1.0), 5.0, 12.0, (0.0, 5.0, 0.0),
            (2.5, -1.5), 0.96, 4.0,
        )
    )  # fmt: skip
    cal = SelfCalEstimate(0.25, 0.02, -0.03, 0.002, 40, 60)
    dkf = json.loads(
        enc.dkf(
            1.0, (1, 2, 3, 4), (5, 6, 7, 8), True, False, 0.04, cal, (0.5, -1, 0), (0.2, 0.3, 0.5),
            -0.75,
        )
    )  # fmt: skip
    assert dkf["target_diameter_m"] == 0.25 and dkf["camera_offset_s"] == -0.03
    assert dkf["target_turn_rate_rad_s"] == -0.75
    for msg, fields, schema in (
        (control, messages.CONTROL, "peregrine.Control"),
        (dkf, messages.DKF, "peregrine.Dkf"),
    ):
        names = [f.name for f in fields]
        assert list(msg) == names == list(SCHEMAS[schema]["properties"])
        for f in fields:
            want = {"number": (int, float), "numbers": list, "string": str, "boolean": bool}
            assert isinstance(msg[f.name], want[f.kind]), f.name
            assert f.unit in SCHEMAS[schema]["properties"][f.name]["description"]
    # missing values are null, never NaN (JSON has no NaN)
    missing = json.loads(
        enc.control(
            1.0, "waiting", "png", math.nan, math.nan, math.nan, math.nan, (0.0, 0.0, 0.0),
            0.0, None, (0.0, 0.0, 0.0), 0.3, 0.0, None, None, None, None, None, None, None,
            math.inf,
        )
    )  # fmt: skip
    assert missing["los_elev_rad"] is None and missing["vel_m_s"] is None
    assert missing["speed_m_s"] is None and missing["e_raw_px"] is None
    assert control["speed_cap_m_s"] == 4.0 and missing["speed_cap_m_s"] is None  # no limit


# ---------------------------------------------------------------- the live telemetry's layout
ROOT = Path(__file__).resolve().parents[1]
WIRE_NAMES = [name for name, _, _ in tm.FIELDS]


def test_the_mavlink_layout_is_derived_from_the_message_definitions():
    assert messages.wire_layout(messages.TELEMETRY) == tm.FIELDS
    assert len(set(WIRE_NAMES)) == len(WIRE_NAMES) <= tm.ARRAY_LEN
    # every float on the link belongs to one defined field, with that field's unit
    owner = {}
    for f in messages.CONTROL + messages.DKF + messages.LINK:
        for i, name in enumerate(f.wire):
            owner.setdefault(name, (f, i))
    for name, unit, meaning in tm.FIELDS:
        f, i = owner[name]
        assert unit == f.element_unit(i) and meaning.startswith(f.meaning), name
    # the recorded control fields the link can carry all travel (the rest are ground-computed)
    sent = {f.name for f in messages.TELEMETRY}
    assert {f.name for f in messages.CONTROL if f.wire} <= sent
    assert {f.name for f in messages.CONTROL if not f.wire} == {
        "accel_normal_m_s2",
        "speed_m_s",
        "range_m",
    }


def test_a_control_tick_round_trips_through_the_link_by_field_definition():
    tel = ControlTelemetry(
        time_s=2.0, mode=LoopMode.TRACKING, law="png", e_est_px=(3.0, -2.0),
        e_rate_est_px_s=(0.5, 0.25), los_elev_rad=0.1, los_azim_rad=0.2, vel_elev_rad=0.3,
        vel_azim_rad=0.4, accel_desired_enu_m_s2=np.array([1.0, 2.0, 3.0]),
        accel_normal_desired_m_s2=1.5, yaw_rate_cmd_rad_s=0.05,
        command=RateThrustCommand(2.0, np.array([0.1, 0.2, 0.3]), 0.6),
        dkf_time_since_detection_s=0.04, dkf_lost=False, guard_tripped=False,
    )  # fmt: skip
    vals = {"t_s": 2.0, **tm.loop_values(tel), **tm.dkf_values((3.0, -2.0, 7.0, 8.0), (1, 2, 3, 4))}
    got = tm.unpack(tm.pack(vals))
    back = telemetry_from_values(got, "png")
    assert back.e_est_px == (3.0, -2.0) and back.e_rate_est_px_s == (0.5, 0.25)
    assert list(back.accel_desired_enu_m_s2) == [1.0, 2.0, 3.0]
    assert list(back.command.body_rates_flu_rad_s) == pytest.approx([0.1, 0.2, 0.3])
    assert back.mode is LoopMode.TRACKING and back.command.thrust_normalised == pytest.approx(0.6)
    fr = live_frame(
        got, law="png", camera=CameraModel(640, 480, 90.0), gains=Gains(), vehicle_p=(0, 0, 0),
        vehicle_v=(1, 0, 0), vehicle_q=(1, 0, 0, 0), target_p=None, normal_accel_m_s2=None,
        acquired=True,
    )  # fmt: skip
    assert fr.dkf_state_px == (3.0, -2.0, 7.0, 8.0) and fr.dkf_cov_diag == (1, 2, 3, 4)


def _sources():
    for d in ("onboard", "groundstation", "web"):
        for p in sorted((ROOT / d).rglob("*")):
            if p.suffix in (".py", ".js", ".html") and p != ROOT / "onboard" / "messages.py":
                yield p


def second_field_lists(text: str) -> list[str]:
    """Places that write two or more of the link's field names as a list (quoted names side by
    side, a tuple of (name, unit, meaning) rows) or build them from pieces (``acc_des_{c}``)."""
    v = "(?:" + "|".join(re.escape(n) for n in WIRE_NAMES) + ")"
    q = r"[\"'`]"
    found = re.findall(q + v + q + r"\s*[,)\]]\s*[(\[]?\s*" + q + v + q, text)
    # a (name, unit, meaning) row opens a tuple or list; names passed as arguments do not
    row = r"[(\[]\s*" + q + v + q + r"\s*,\s*" + q + r"[^\"'`]{0,12}" + q + r"\s*,\s*" + q
    found += re.findall(row, text)
    found += re.findall(r"f" + q + r"[a-z_]*\{[^}]*\}_(?:m|px|rad|m_s|m_s2|rad_s|px_s)\b", text)
    return found


def test_no_second_list_of_the_link_fields(tmp_path):
    # the check finds what it must: the list this module once had, and pieced-together names
    assert second_field_lists('FIELDS = (("t_s", "s", "clock"), ("state", "-", "code"))')
    assert second_field_lists('p = [t.get("pos_e_m"), t.get("pos_n_m")]') == []  # see below
    assert second_field_lists('keys = ("pos_e_m", "pos_n_m", "pos_u_m")')
    assert second_field_lists('[t.get(f"acc_des_{c}_m_s2") for c in "enu"]')
    assert second_field_lists('group(rows, "law", "elev_deg", "azim_deg")') == []  # keys
    offenders = {
        str(p.relative_to(ROOT)): hits
        for p in _sources()
        if (hits := second_field_lists(p.read_text(encoding="utf-8")))
    }
    assert offenders == {}
    # names read one by one are fine, but vectors are read through their field's wire names
    for p in _sources():
        text = p.read_text(encoding="utf-8")
        for vec in ("pos_e_m", "vel_e_m_s", "q_w", "acc_des_e_m_s2", "rate_cmd_x_rad_s"):
            assert f'"{vec}"' not in text, (p, vec)
