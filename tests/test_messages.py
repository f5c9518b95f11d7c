"""One definition per recorded controller message (onboard/messages.py): the MCAP schemas are
derived from it and the encoders write exactly its fields, in its order."""

import json
import math

from groundstation.recording import encode as enc
from groundstation.recording.schemas import SCHEMAS
from onboard import messages


def test_schemas_and_encoders_follow_the_one_definition():
    control = json.loads(
        enc.control(
            1.0, "tracking", "png", 0.1, 0.2, 0.3, 0.4, (1.0, 2.0, 3.0), 1.5, 1.2,
            (0.1, 0.2, 0.3), 0.5, 0.05, (3.0, -2.0), (1.0, 1.0), 5.0, 12.0, (0.0, 5.0, 0.0),
            (2.5, -1.5), 0.96,
        )
    )  # fmt: skip
    dkf = json.loads(enc.dkf(1.0, (1, 2, 3, 4), (5, 6, 7, 8), True, False, 0.04))
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
        )
    )  # fmt: skip
    assert missing["los_elev_rad"] is None and missing["vel_m_s"] is None
    assert missing["speed_m_s"] is None and missing["e_raw_px"] is None
