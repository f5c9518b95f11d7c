"""Every enumeration has one source (onboard/enums.py): the MAVLink codes, the law table, the
CLI, the campaigns and the page's option lists derive from it, and no second list of its
values is written anywhere in the product's code or pages."""

import enum
import re
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from groundstation.app.server import GroundStation
from groundstation.app.session import SPEEDS
from groundstation.campaigns.definitions import LAWS
from groundstation.campaigns.report import LAW_COLOURS, LAW_NAMES
from groundstation.cli import _build_parser as build_parser
from groundstation.sim.camera import CAMERA_MODES
from groundstation.sim.simulation import Outcome as SimOutcome
from onboard import enums
from onboard.control.guidance import GUIDANCE_LAWS
from onboard.datatypes import LoopMode as DatatypesLoopMode
from onboard.link import params as prm
from onboard.link import telemetry as tm
from onboard.runtime.state_machine import State

ROOT = Path(__file__).resolve().parents[1]
ENUMS = (enums.GuidanceLaw, enums.LoopMode, enums.RuntimeState, enums.Outcome)
SOURCES = [
    p
    for d in ("onboard", "groundstation", "web")
    for p in sorted((ROOT / d).rglob("*"))
    if p.suffix in (".py", ".js", ".html") and p != ROOT / "onboard" / "enums.py"
]


def test_codes_and_tables_derive_from_the_enums():
    assert tm.LAW_CODES == tuple(m.value for m in enums.GuidanceLaw) == LAWS
    assert tuple(m.value for m in enums.LoopMode) == tm.LOOP_MODE_CODES
    assert tuple(m.value for m in enums.RuntimeState) == tm.STATE_CODES
    assert set(GUIDANCE_LAWS) == set(tm.LAW_CODES) == set(LAW_NAMES) == set(LAW_COLOURS)
    assert State is enums.RuntimeState and DatatypesLoopMode is enums.LoopMode
    assert SimOutcome is enums.Outcome
    assert prm.RuntimeParams(LAW=2).law == "ibvs"
    assert prm.law_name(0.0) == "png" and prm.law_name(3.0) == "apn"  # a code said is kept
    # the field help and the parameter help state the codes as the enums number them
    assert tm.FIELDS[tm.INDEX["law"]][2].endswith("0 png, 1 pg, 2 ibvs, 3 apn")
    assert "3 brake" in tm.FIELDS[tm.INDEX["loop_mode"]][2]
    sortie = build_parser().parse_args(["sortie", "cv-top-to-bottom", "--law", "pg"])
    assert sortie.law == "pg"
    assert build_parser().parse_args(["campaign", "static"]).laws == "png,pg,ibvs"


def test_the_api_serves_the_option_lists(tmp_path):
    gs = GroundStation(port=0, data_dir=tmp_path, log_dir=tmp_path / "logs")
    try:
        with TestClient(gs.app, base_url="http://127.0.0.1") as c:
            assert c.get("/api/meta").status_code == 401  # behind the token like the rest
            c.headers["Authorization"] = f"Bearer {gs.token}"
            meta = c.get("/api/meta").json()
    finally:
        gs.close()
    assert meta == {
        "laws": ["png", "pg", "ibvs", "apn"],
        "loop_modes": ["waiting", "tracking", "lost", "brake", "coast", "reacquire", "search"],
        "runtime_states": list(tm.STATE_CODES),
        "outcomes": ["HIT", "MISS", "TIMEOUT", "TARGET_LOST", "CRASHED", "DIVERGED"],
        "camera_modes": list(CAMERA_MODES),
        "speeds": list(SPEEDS),
        "defaults": {"laws": enums.DEFAULT_LAW.value, "camera_modes": "projected", "speeds": "1"},
    }


def second_lists(text: str, enumeration: type[enum.Enum]) -> list[str]:
    """Places in ``text`` that write two or more of the enumeration's values as a list: quoted
    strings side by side (a tuple, a list, a set, even across lines), ``<option>``s one after
    the other, or a comma-joined string. (Data keyed by a value, ``{"png": 0.09, ...}``, is
    not a list.)"""
    v = "(?:" + "|".join(re.escape(str(m.value)) for m in enumeration) + ")"
    q = r"[\"'`]"
    patterns = (
        q + v + q + r"\s*[,|]\s*" + q + v + q,  # ("png", "pg") ["png", "pg"] "png" | "pg"
        r"<option[^>]*>\s*" + v + r"\s*</option>\s*<option[^>]*>\s*" + v,
        q + v + r"(?:,\s*" + v + r")+" + q,  # "png,pg,ibvs"
    )
    found = []
    for pattern in patterns:
        for m in re.finditer(pattern, text):
            line = text.count("\n", 0, m.start()) + 1
            found.append(f"{line}: {m.group(0)}")
    return found


@pytest.mark.parametrize("enumeration", ENUMS, ids=lambda e: e.__name__)
def test_no_second_list_of_any_enum(enumeration):
    hits = {
        str(p.relative_to(ROOT)): h
        for p in SOURCES
        if (h := second_lists(p.read_text(encoding="utf-8"), enumeration))
    }
    assert not hits, f"a second list of {enumeration.__name__} (derive it from onboard/enums.py)"


def test_the_scan_finds_a_second_list():
    """The test above can fail: each way of writing a list is caught."""
    law = enums.GuidanceLaw
    assert second_lists('LAWS = ("png", "pg", "ibvs")', law)
    assert second_lists("<select><option>png</option><option>pg</option></select>", law)
    assert second_lists('c.add_argument("--laws", default="png,pg,ibvs")', law)
    assert second_lists("MODES = [\n    'waiting',\n    'tracking',\n]", enums.LoopMode)
    assert second_lists('state in ("ready", "waiting_target")', enums.RuntimeState)
    assert not second_lists('law = "png"  # the proposed law', law)
    assert not second_lists("LAWS = codes(GuidanceLaw)", law)


def law_defaults() -> dict[str, object]:
    """Every place that flies a law when none is named, and the law it would fly."""
    import inspect

    from groundstation.app.api_models import ReflyRequest, StartRequest
    from groundstation.app.session_config import SortieConfig
    from groundstation.campaigns.tune import TuneDefinition
    from groundstation.sim.beliefs import loop_configuration
    from groundstation.sim.simulation import Simulation, run_sortie
    from onboard.loop import InterceptionLoop

    def default(f):
        return inspect.signature(f).parameters["law"].default

    return {
        "InterceptionLoop": default(InterceptionLoop),
        "Simulation": default(Simulation),
        "run_sortie": default(run_sortie),
        "loop_configuration": default(loop_configuration),
        "SortieConfig": SortieConfig.law,
        "TuneDefinition": TuneDefinition.law,
        "StartRequest": StartRequest.model_fields["law"].default,
        "ReflyRequest": ReflyRequest.model_fields["law"].default,
        "sortie --law": build_parser().parse_args(["sortie", "cv-top-to-bottom"]).law,
        "tune --law": build_parser().parse_args(["tune", "cv-top-to-bottom", "--gains", "K_y"]).law,
        "parameter LAW": prm.RuntimeParams().law,
        "a live vehicle that has not said": prm.law_name(None),
        "a live vehicle that sent NaN": prm.law_name(float("nan")),
    }


def test_the_default_law_is_declared_once():
    """Every default law is onboard/enums.py's DEFAULT_LAW; no product file writes its own
    (``law: str = "png"``, ``default="png"``)."""
    assert law_defaults() == dict.fromkeys(law_defaults(), enums.DEFAULT_LAW.value)
    own = re.compile(r"law\w*\s*(?::\s*\w+\s*)?=\s*[\"'](?:" + "|".join(tm.LAW_CODES) + r")[\"']")
    texts = {p: p.read_text(encoding="utf-8") for p in SOURCES}
    hits = [
        f"{p.relative_to(ROOT)}:{text.count(chr(10), 0, m.start()) + 1}"
        for p, text in texts.items()
        for m in own.finditer(text)
    ]
    assert not hits, f"a default law written outside onboard/enums.py: {hits}"
