"""The onboard component's parameters as third-party ground stations see them: PX4-style ids,
old params files still loading, MAVLink FTP (param.pck, component metadata), and real
clients from PyPI (pymavlink's mavutil/mavparm and mavftp; the pinned MAVProxy, installed
apart) against an ``onboard run`` process."""

from __future__ import annotations

import json
import os
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from pymavlink import mavftp, mavparm, mavutil

from onboard.gains import GAIN_SPECS, GainError, Gains
from onboard.link import ftp
from onboard.link.param_meta import FILE_NAMES, component_files, parameter_metadata
from onboard.link.params import PARAM_IDS, PARAM_NAMES, PARAM_SPECS, ParamTable

from .sitl_rig import free_port

ROOT = Path(__file__).resolve().parent.parent


# ---------------------------------------------------------------------- the names
def test_every_parameter_has_a_px4_style_id_derived_from_its_python_name():
    ids = [s.param_id for s in PARAM_SPECS]
    assert len(set(ids)) == len(ids) == len(PARAM_SPECS)
    for s in PARAM_SPECS:
        assert s.param_id.startswith("PRG_") and s.param_id.isupper() and len(s.param_id) <= 16
        assert PARAM_NAMES[s.param_id] == s.name and PARAM_IDS[s.name] == s.param_id
    assert PARAM_IDS["k_a"] == "PRG_K_A" and PARAM_IDS["K_y"] == "PRG_K_Y"
    assert (
        PARAM_IDS["omega_max"] == "PRG_OMEGA_MAX" and PARAM_IDS["CAM_PITCH_DEG"] == "PRG_CAM_PITCH"
    )
    assert {s.name for s in GAIN_SPECS} <= set(PARAM_IDS)


def test_an_old_params_file_still_loads_with_a_deprecation_note(tmp_path):
    path = tmp_path / "params.toml"
    path.write_text("k_a = 3.5\nK_y = 4\nLAW = 1\nPRG_V_MAX = 9\n")
    table = ParamTable(path)
    assert table.gains.k_a == 3.5 and table.gains.K_y == 4.0 and table.gains.v_max == 9.0
    assert table.runtime.law == "pg"
    assert len(table.notes) == 3
    assert any("k_a is deprecated, use PRG_K_A" in n for n in table.notes)
    assert table.set("k_d", 0.02, flying=False) == (True, "")
    text = path.read_text()  # rewritten with the new ids only
    assert "PRG_K_A = 3.5" in text and "PRG_LAW = 1.0" in text and "\nk_a" not in text
    assert ParamTable(path).notes == []
    path.write_text("k_a = 3.5\nPRG_K_A = 2\n")
    with pytest.raises(GainError, match="old and its new name"):
        ParamTable(path)
    path.write_text("PRG_K_A = 11\n")
    with pytest.raises(GainError, match="k_a"):
        ParamTable(path)


# ---------------------------------------------------------------------- FTP, pure
def _request(seq, opcode, session=0, offset=0, data=b"", size=None):
    n = len(data) if size is None else size
    head = ftp.HEADER.pack(seq, session, opcode, n, 0, 0, 0, offset)
    return head + data + bytes(ftp.PAYLOAD_LEN - len(head) - len(data))


def _unpack(reply):
    seq, session, opcode, size, req, burst, _, offset = ftp.HEADER.unpack_from(reply)
    return seq, session, opcode, size, req, burst, offset, reply[ftp.HEADER.size :][:size]


def test_ftp_serves_the_parameter_pack_and_naks_what_it_cannot_do():
    table = ParamTable()
    server = ftp.FtpServer(component_files(table.get), FILE_NAMES)
    (open_ack,) = server.handle(_request(7, ftp.OP_OPEN_FILE_RO, data=b"@PARAM/param.pck\0"))
    seq, session, op, size, req, _, _, body = _unpack(open_ack)
    assert (seq, op, size, req) == (8, ftp.OP_ACK, 4, ftp.OP_OPEN_FILE_RO)
    length = struct.unpack("<I", body)[0]
    burst = server.handle(_request(9, ftp.OP_BURST_READ_FILE, session, size=100))
    data = b"".join(_unpack(r)[7] for r in burst)
    assert len(data) == length and [_unpack(r)[0] for r in burst] == list(
        range(10, 10 + len(burst))
    )
    assert [_unpack(r)[5] for r in burst] == [0] * (len(burst) - 1) + [1]  # burst complete
    pdata = mavftp.MAVFTP.ftp_param_decode(data)  # pymavlink's own decoder
    values = {n.decode(): v for n, v, _ in pdata.params}
    assert set(values) == set(PARAM_NAMES)
    assert values["PRG_K_A"] == pytest.approx(Gains().k_a)
    (eof,) = server.handle(_request(11, ftp.OP_READ_FILE, session, offset=length, size=50))
    assert _unpack(eof)[2] == ftp.OP_NAK and _unpack(eof)[7] == bytes([ftp.ERR_EOF])
    assert _unpack(server.handle(_request(12, ftp.OP_TERMINATE_SESSION, session))[0])[2] == 128
    for request, error in (
        (_request(1, ftp.OP_OPEN_FILE_RO, data=b"/etc/passwd\0"), ftp.ERR_FILE_NOT_FOUND),
        (_request(2, 6, data=b"x\0"), ftp.ERR_UNKNOWN_COMMAND),  # CreateFile: read-only
        (_request(3, ftp.OP_READ_FILE, session=3), ftp.ERR_INVALID_SESSION),
    ):
        (nak,) = server.handle(request)
        assert _unpack(nak)[2] == ftp.OP_NAK and _unpack(nak)[7] == bytes([error])
    (listing,) = server.handle(_request(4, ftp.OP_LIST_DIRECTORY, data=b"/\0"))
    names = _unpack(listing)[7].split(b"\0")
    assert b"D@PARAM" in names and any(n.startswith(b"Fparam.json\t") for n in names)


def test_parameter_metadata_follows_mavlinks_component_metadata_schema():
    doc = parameter_metadata()
    allowed = {"name", "type", "shortDesc", "longDesc", "units", "default", "decimalPlaces",
               "min", "max", "increment", "rebootRequired", "group", "category", "volatile",
               "values", "bitmask", "readOnly"}  # fmt: skip
    assert doc["version"] >= 3 and set(doc) == {"version", "parameters"}
    by_name = {p["name"]: p for p in doc["parameters"]}
    assert set(by_name) == set(PARAM_NAMES)
    for s in PARAM_SPECS:
        p = by_name[s.param_id]
        assert set(p) <= allowed and p["type"] == "Float"
        assert (p["default"], p["min"], p["max"]) == (s.default, s.minimum, s.maximum)
        assert p["shortDesc"] and s.meaning in p["longDesc"] and p["group"].startswith("Peregrine")
    assert by_name["PRG_K_A"]["units"] == "m/s^2"


# ---------------------------------------------------------------------- real clients
@pytest.fixture
def onboard(tmp_path):
    """``onboard run`` with no flight controller and no camera, its ground link on a port."""
    port = free_port()
    params = tmp_path / "params.toml"
    params.write_text("k_a = 2.5\n")  # an old file: still loads
    out = (tmp_path / "onboard.log").open("w")
    proc = subprocess.Popen(
        [sys.executable, "-m", "onboard", "run", "--camera", "sitl://127.0.0.1:9",
         "--mavlink", f"udpout:127.0.0.1:{free_port()}", "--gcs", f"udpout:127.0.0.1:{port}",
         "--params", str(params), "--rate", "50"],
        stdout=out, stderr=subprocess.STDOUT, env=dict(os.environ, PYTHONUNBUFFERED="1"),
    )  # fmt: skip
    try:
        yield port, params, tmp_path / "onboard.log"
    finally:
        proc.terminate()
        proc.wait(10)
        out.close()


def _connect(port: int):
    master = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=255)
    hb = master.recv_match(type="HEARTBEAT", blocking=True, timeout=10)
    assert hb is not None and hb.get_srcComponent() == 191
    master.target_system, master.target_component = 1, 191
    return master


def test_pymavlink_fetches_shows_and_sets_every_parameter(onboard):
    port, params, log = onboard
    master = _connect(port)
    try:
        master.param_fetch_all()
        got: dict[str, float] = {}
        end = time.monotonic() + 10
        while len(got) < len(PARAM_SPECS) and time.monotonic() < end:
            m = master.recv_match(type="PARAM_VALUE", blocking=True, timeout=1)
            if m is not None:
                got[m.param_id] = m.param_value
        assert set(got) == set(PARAM_NAMES)
        assert got["PRG_K_A"] == 2.5  # from the old file
        mav_param = mavparm.MAVParmDict()
        mav_param.update(got)
        assert mav_param.mavset(master, "PRG_K_Y", 4.5, retries=3)
        assert mav_param["PRG_K_Y"] == 4.5
        assert not mav_param.mavset(master, "PRG_NOPE", 1.0, retries=1)
        assert "PRG_K_Y = 4.5" in params.read_text()
        assert "k_a is deprecated, use PRG_K_A" in log.read_text()
    finally:
        master.close()


def test_pymavlink_mavftp_downloads_parameters_and_metadata(onboard, tmp_path):
    port, _, _ = onboard
    master = _connect(port)
    try:
        client = mavftp.MAVFTP(master, 1, 191)
        values, defaults = tmp_path / "values.param", tmp_path / "defaults.param"
        client.cmd_getparams([str(values), str(defaults)])
        ret = client.process_ftp_reply("OpenFileRO", timeout=10)
        assert ret.error_code == 0, ret.display_message()
        text = values.read_text()
        assert "PRG_K_A" in text and "PRG_HOLD_SPEED" in text
        assert "PRG_K_A,2" in defaults.read_text().replace(" ", "").replace("\t", ",")
        for name in ("general.json", "param.json"):
            local = tmp_path / name
            client.cmd_get([name, str(local)])
            ret = client.process_ftp_reply("OpenFileRO", timeout=10)
            assert ret.error_code == 0
            doc = json.loads(local.read_text())
        assert {p["name"] for p in doc["parameters"]} == set(PARAM_NAMES)
        client.cmd_get(["@SYS/nothing.txt", str(tmp_path / "x")])
        assert client.process_ftp_reply("OpenFileRO", timeout=5).error_code != 0
    finally:
        master.close()


# MAVProxy itself, pinned, and the pure-Python modules it imports to run on a console with
# its default modules (no map, console or other GUI module): its own requirements add
# opencv-python, VTK and matplotlib, and opencv-python would replace the project's
# opencv-python-headless, so it is installed apart, without them.
MAVPROXY = ("MAVProxy==1.8.75", "pyserial==3.5", "defusedxml==0.7.1")


@pytest.fixture(scope="session")
def mavproxy(tmp_path_factory) -> tuple[list[str], dict[str, str]]:
    """(command, environment) running the pinned MAVProxy from a directory of its own
    (``pip install --no-deps --target``), with this environment's pymavlink and numpy. An
    install failure fails the test under CI and skips it elsewhere (offline)."""
    target = tmp_path_factory.mktemp("mavproxy")
    got = subprocess.run(
        [sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--no-compile",
         "--target", str(target), *MAVPROXY],
        capture_output=True, text=True,
    )  # fmt: skip
    if got.returncode != 0:
        why = f"pip install {' '.join(MAVPROXY)} failed: {got.stderr.strip()[-500:]}"
        if os.environ.get("CI"):
            pytest.fail(why)
        pytest.skip(why)
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(target), env.get("PYTHONPATH")]))
    return [sys.executable, str(target / "bin" / "mavproxy.py")], env


def test_mavproxy_fetches_over_ftp_shows_and_sets_a_gain(onboard, tmp_path, mavproxy):
    """MAVProxy with its default modules, driven on stdin as an operator would type (the
    pinned release, installed apart: see :data:`MAVPROXY`)."""
    port, params, _ = onboard
    command, env = mavproxy
    proc = subprocess.Popen(
        [*command, f"--master=udpin:127.0.0.1:{port}", "--source-system=255",
         "--target-system=1", "--target-component=191", "--nowait",
         f"--state-basedir={tmp_path}"],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        cwd=tmp_path, env=env,
    )  # fmt: skip
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(proc.stdout), daemon=True)
    reader.start()

    def wait(pred, timeout_s, what):
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            if pred():
                return time.monotonic()
            time.sleep(0.05)
        raise AssertionError(f"MAVProxy: no {what}\n" + "".join(lines))

    def say(command: str) -> None:
        proc.stdin.write(command + "\n")
        proc.stdin.flush()

    try:
        t0 = time.monotonic()
        fetched = wait(lambda: any("parameters (ftp)" in ln for ln in lines), 30, "FTP fetch")
        assert any(f"Received {len(PARAM_SPECS)} parameters (ftp)" in ln for ln in lines)
        assert fetched - t0 < 15  # no FTP timeout and fallback on the way
        say("param set PRG_K_Y 4.25")
        wait(lambda: "PRG_K_Y = 4.25" in params.read_text(), 10, "PARAM_SET applied")
        say("param show PRG_K_Y")
        wait(lambda: any(ln.split()[-2:] == ["PRG_K_Y", "4.25"] for ln in lines), 10, "show")
    finally:
        proc.kill()
        proc.wait(10)
