"""The parameter table as files ground stations fetch over MAVLink FTP (:mod:`.ftp`), derived
from :data:`.params.PARAM_SPECS` (itself from ``onboard/gains.py``), never written by hand:

- ``@PARAM/param.pck``: every value (and default) packed as ArduPilot's parameter download
  does, which MAVProxy and pymavlink's ``mavftp`` fetch first (``param fetch``);
- ``general.json`` and ``param.json``: MAVLink component metadata (COMP_METADATA_TYPE_GENERAL
  and _PARAMETER, https://mavlink.io/en/services/component_information.html), the format
  QGroundControl reads for description, unit, range, default and group.
"""

from __future__ import annotations

import json
import struct
import zlib
from collections.abc import Callable

from .params import PARAM_SPECS

PCK_MAGIC = 0x671B
PCK_MAGIC_DEFAULTS = 0x671C
PCK_TYPE_FLOAT = 4
METADATA_TYPE_GENERAL = 0  # COMP_METADATA_TYPE
METADATA_TYPE_PARAMETER = 1
COMPONENT_ID = 191  # MAV_COMP_ID_ONBOARD_COMPUTER (kept here to stay free of pymavlink)


def param_pck(get: Callable[[str], float], with_defaults: bool = False) -> bytes:
    """Every parameter (``get(python_name)`` gives its value) in the ``param.pck`` layout:
    header (magic, count, total), then per parameter a type byte (flags in the high nibble:
    1 = a default follows), a byte (suffix length - 1) << 4 | length shared with the previous
    name, the name's suffix, the value (and default) as little-endian float32."""
    specs = sorted(PARAM_SPECS, key=lambda s: s.param_id)
    out = bytearray(
        struct.pack(
            "<HHH", PCK_MAGIC_DEFAULTS if with_defaults else PCK_MAGIC, len(specs), len(specs)
        )
    )
    last = b""
    for s in specs:
        name = s.param_id.encode("ascii")
        common = 0
        while common < min(len(name) - 1, len(last), 15) and name[common] == last[common]:
            common += 1
        suffix = name[common:]
        flags = 1 if with_defaults else 0
        out += bytes([PCK_TYPE_FLOAT | flags << 4, (len(suffix) - 1) << 4 | common]) + suffix
        out += struct.pack("<f", get(s.name))
        if with_defaults:
            out += struct.pack("<f", s.default)
        last = name
    return bytes(out)


def _decimals(s) -> int:
    text = f"{s.default:.7g}"
    return max(len(text.partition(".")[2]), 3 if s.maximum - s.minimum <= 1 else 2)


def parameter_metadata() -> dict:
    """COMP_METADATA_TYPE_PARAMETER (mavlink/component_metadata/parameter.schema.json)."""
    params = []
    for s in PARAM_SPECS:
        short = s.meaning.split(":")[0].split(" (")[0]
        params.append(
            {
                "name": s.param_id,
                "type": "Float",
                "shortDesc": short[:1].upper() + short[1:],
                "longDesc": f"{s.meaning}. Python name {s.name}; "
                + (
                    "applied at the next control tick." if s.live else "changes on the ground only."
                ),
                "units": "" if s.unit == "-" else s.unit,
                "default": s.default,
                "min": s.minimum,
                "max": s.maximum,
                "decimalPlaces": _decimals(s),
                "group": f"Peregrine {s.group}",
                "category": "Standard" if s.live else "Advanced",
            }
        )
    return {"version": 3, "parameters": params}


def _json_bytes(doc: dict) -> bytes:
    return json.dumps(doc, indent=1).encode("utf-8")


def general_metadata() -> dict:
    """COMP_METADATA_TYPE_GENERAL: where the parameter metadata is (MAVLink FTP on this
    component), with its CRC32."""
    param = _json_bytes(parameter_metadata())
    return {
        "version": 1,
        "vendorName": "Peregrine",
        "modelName": "Peregrine onboard interception loop",
        "metadataTypes": [
            {
                "type": METADATA_TYPE_PARAMETER,
                "uri": f"mftp://[;comp={COMPONENT_ID}]param.json",
                "fileCrc": zlib.crc32(param),
            }
        ],
    }


def component_files(get: Callable[[str], float]) -> Callable[[str], bytes | None]:
    """The read-only files the onboard component serves over FTP: ``path`` (with an optional
    ``?query``) -> contents, or ``None`` for no such file."""

    def read(path: str) -> bytes | None:
        name, _, query = path.lstrip("/").partition("?")
        if name == "@PARAM/param.pck":
            return param_pck(get, with_defaults="withdefaults=1" in query.split("&"))
        if name == "general.json":
            return _json_bytes(general_metadata())
        if name == "param.json":
            return _json_bytes(parameter_metadata())
        return None

    return read


FILE_NAMES = ("@PARAM/param.pck", "general.json", "param.json")
