"""Every entry point refuses bad input cleanly: the command line (one line naming the option,
exit 2, before any work), scenario TOML and --set (property tests: only ScenarioError, always
located), and damaged sortie logs (a precise message and what was recovered)."""

import json
import os
import socket
import string
import subprocess
import sys
import time

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from groundstation.cli import main
from groundstation.recording.reader import LogError, LogIndex, inspect_log, iter_messages
from groundstation.scenario import (
    SCENARIO_DIR,
    ScenarioError,
    load_scenario,
    parse_overrides,
    parse_scenario,
    with_overrides,
)

from .cli_support import run_cli


def _run(capsys, *argv) -> tuple[int, str, str]:
    return run_cli(main, argv, capsys)


# ----------------------------------------------------------------------------- command line
@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (
            ["sortie", "static-ahead-20m", "--seed", "-1"],
            "argument --seed: must be an integer >= 0",
        ),
        (["campaign", "static", "--seed", "-5"], "argument --seed: must be an integer >= 0"),
        (["campaign", "static", "--workers", "0"], "argument --workers: must be an integer >= 1"),
        (["campaign", "static", "--n", "0"], "argument --n: must be an integer >= 1"),
        (["campaign", "static", "--n", "x"], "argument --n: must be an integer >= 1, got 'x'"),
        (["serve", "--port", "99999"], "argument --port: must be an integer from 0 to 65535"),
        (["serve", "--port", "-1"], "argument --port: must be an integer from 0 to 65535"),
        (["sitl", "--camera-port", "70000"], "argument --camera-port: must be an integer from 0"),
        (["sitl", "--duration", "nan"], "argument --duration: must be a number of seconds > 0"),
        (["sitl", "--offboard-loss", "0"], "argument --offboard-loss: must be a number of seconds"),
        (["sitl", "--camera-blackout-after", "-1"], "argument --camera-blackout-after: must be"),
        (["bench", "--repeat", "0"], "argument --repeat: must be an integer >= 1"),
        (["bench", "--sitl", "--seconds", "inf"], "argument --seconds: must be a number"),
        (["sortie", "no-such-scenario"], "no such file or shipped scenario (shipped: "),
        (["sortie", "static-ahead-20m", "--law", "x"], "argument --law: invalid choice"),
        (["sortie", "static-ahead-20m", "--set", "gains.k_v=abc"], "gains.k_v: 'abc' is not a"),
        (["sortie", "static-ahead-20m", "--set", "gains.k_v=1000"], "gain k_v = 1000.0 is outside"),
        (["campaign", "nope"], "unknown campaign 'nope'"),
        (["campaign", "static", "--laws", "png,zz"], "unknown law(s) zz"),
    ],
)
def test_bad_options_get_one_line_and_exit_2(capsys, argv, needle):
    code, out, err = _run(capsys, *argv)
    assert code == 2, err
    assert needle in err and "Traceback" not in err and out == ""


def test_paths_must_exist_and_be_of_the_right_kind(capsys, tmp_path):
    a_file = tmp_path / "f.txt"
    a_file.write_text("x")
    cases = [
        (["replay", str(tmp_path)], f"argument file: {tmp_path} is a folder"),
        (["replay", str(tmp_path / "none.mcap")], "none.mcap: no such file"),
        (["sortie", str(tmp_path)], "is a folder; give a scenario TOML file or name"),
        (["serve", "--log-dir", str(a_file)], "argument --log-dir: " + str(a_file) + " is a file"),
        (["serve", "--log-dir", "/proc/peregrine/logs"], "argument --log-dir: /proc/peregrine"),
        (["serve", "--data-dir", str(a_file / "x")], "argument --data-dir: "),
        (["serve", "--signing-key", str(tmp_path / "k")], "argument --signing-key: "),
        (["sortie", "static-ahead-20m", "--log", str(a_file)], "argument --log: "),
        (["campaign", "static", "--out", str(a_file)], "argument --out: "),
    ]
    for argv, needle in cases:
        code, out, err = _run(capsys, *argv)
        assert code == 2 and needle in err and out == "", (argv, err)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f.txt"]  # nothing was created


def test_a_port_in_use_names_the_port_and_prints_no_url(tmp_path, capsys):
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        code, out, err = _run(
            capsys, "serve", "--port", str(port), "--data-dir", str(tmp_path),
            "--log-dir", str(tmp_path / "logs"),
        )  # fmt: skip
    assert code == 2 and out == ""  # no URL
    assert f"argument --port: port {port} on 127.0.0.1 is in use" in err
    assert "--port 0 for any free port" in err and "Traceback" not in err


def test_port_0_prints_the_port_the_server_took_and_it_answers(tmp_path):
    # the advice above: the URL printed must carry the free port taken, not 0
    import re
    import urllib.request

    proc = subprocess.Popen(
        [sys.executable, "-m", "groundstation", "serve", "--port", "0",
         "--data-dir", str(tmp_path), "--log-dir", str(tmp_path / "logs")],
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, cwd=tmp_path,
        env=dict(os.environ, PYTHONUNBUFFERED="1"),
    )  # fmt: skip
    try:
        line = proc.stdout.readline()
        m = re.search(r"http://127\.0\.0\.1:(\d+)/\?token=(\S+)", line)
        assert m and int(m.group(1)) > 0, line
        req = urllib.request.Request(
            f"http://127.0.0.1:{m.group(1)}/api/status",
            headers={"Authorization": f"Bearer {m.group(2)}"},
        )
        end, status = time.monotonic() + 60, None
        while status is None and time.monotonic() < end:
            try:
                with urllib.request.urlopen(req, timeout=5) as r:
                    status = r.status
            except OSError:
                time.sleep(0.1)  # not serving yet
        assert status == 200
    finally:
        proc.terminate()
        proc.wait(15)


def test_help_imports_none_of_the_heavy_libraries():
    code = (
        "import sys\nfrom groundstation.cli import main\n"
        "try:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
        "main(['scenarios'])\n"
        "print('HEAVY', sorted(m for m in ('numpy', 'scipy', 'filterpy', 'cv2', 'viser',"
        " 'matplotlib') if m in sys.modules))"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert "HEAVY []" in r.stdout and "static-ahead-20m" in r.stdout


# ----------------------------------------------------------------------------- scenarios
BAD = """\
name = "many-problems"
duration_s = "long"
[interceptor]
position_m = [0.0, 0.0, -1.0]
[target]
motion = "teleport"
position_m = [0.0, 25.0, 1.0]
colour = "red"
[camera]
rate_hz = 7
[gains]
K_y = 50
"""


def test_every_problem_is_reported_at_once_with_its_line():
    with pytest.raises(ScenarioError) as exc:
        parse_scenario(BAD, "bad.toml")
    found = {p.key: p.line for p in exc.value.problems}
    assert found == {
        "duration_s": 2,
        "interceptor.position_m": 4,
        "target.motion": 6,
        "target.colour": 8,
        "camera.rate_hz": 10,
        "gains.K_y": 12,
    }
    lines = str(exc.value).splitlines()
    assert len(lines) == 6 and all(line.startswith("bad.toml: line ") for line in lines)
    assert "bad.toml: line 6: key 'target.motion': must be one of" in str(exc.value)
    assert isinstance(exc.value, ValueError)  # callers catching ValueError keep working


def test_a_syntax_error_has_line_and_column():
    with pytest.raises(ScenarioError) as exc:
        parse_scenario('name = "x"\nduration_s = 3\n[target\n', "bad.toml")
    (p,) = exc.value.problems
    assert (p.line, p.column) == (3, 8) and p.message.startswith("not valid TOML")
    assert str(exc.value).startswith("bad.toml: line 3, column 8: not valid TOML")


def test_the_cli_and_the_api_get_the_same_problems(capsys, tmp_path):
    from fastapi.testclient import TestClient

    from groundstation.app.server import GroundStation

    path = tmp_path / "bad.toml"
    path.write_text(BAD)
    code, _, err = _run(capsys, "sortie", str(path))
    assert code == 2 and len(err.strip().splitlines()) == 6
    gs = GroundStation(port=0, data_dir=tmp_path, log_dir=tmp_path / "logs")
    try:
        with TestClient(gs.app, base_url="http://127.0.0.1") as c:
            c.headers["Authorization"] = f"Bearer {gs.token}"
            r = c.post("/api/scenarios/validate", json={"toml": BAD})
            assert r.status_code == 422
            body = r.json()
            expected = parse_problems(BAD)
            assert body["problems"] == expected and body["detail"].count("\n") == 5
            r = c.post("/api/sortie/start", json={"toml": BAD})
            assert r.status_code == 422 and r.json()["problems"] == expected
            assert c.get("/api/status").json()["state"] == "idle"  # nothing started
    finally:
        gs.close()


def parse_problems(text):
    try:
        parse_scenario(text, "uploaded scenario")
    except ScenarioError as exc:
        return [p.to_json_dict() for p in exc.problems]
    raise AssertionError("expected problems")


_GOOD_TEXTS = [p.read_text() for p in sorted(SCENARIO_DIR.glob("*.toml"))]


def _assert_located(exc: ScenarioError, text: str) -> None:
    assert exc.problems
    n_lines = max(1, text.count("\n") + 1)
    for p in exc.problems:
        assert p.key is not None or p.line is not None, p
        if p.line is not None:
            assert 1 <= p.line <= n_lines, (p, n_lines)
    assert str(exc)


@st.composite
def _mutated(draw):
    text = draw(st.sampled_from(_GOOD_TEXTS))
    for _ in range(draw(st.integers(1, 4))):
        lines = text.split("\n")
        i = draw(st.integers(0, len(lines) - 1))
        op = draw(st.sampled_from(["drop", "dup", "chars", "value", "swap"]))
        if op == "drop":
            del lines[i]
        elif op == "dup":
            lines.insert(i, lines[i])
        elif op == "chars":
            line = lines[i]
            j = draw(st.integers(0, len(line)))
            junk = draw(st.text(alphabet=string.printable, max_size=4))
            lines[i] = line[:j] + junk + line[j + draw(st.integers(0, 3)) :]
        elif op == "value" and "=" in lines[i]:
            key = lines[i].split("=", 1)[0]
            value = draw(
                st.sampled_from(['"x"', "-1", "0", "1e400", "nan", "inf", "[1, 2]", "true",
                                 "[]", "{}", "1979-05-27", "99999999999999999999", "-0.0"])
            )  # fmt: skip
            lines[i] = f"{key}= {value}"
        elif op == "swap" and len(lines) > 1:
            k = draw(st.integers(0, len(lines) - 1))
            lines[i], lines[k] = lines[k], lines[i]
        text = "\n".join(lines)
    return text


_FUZZ_SETTINGS = settings(
    max_examples=300, deadline=None, derandomize=True, database=None,
    suppress_health_check=list(HealthCheck),
)  # fmt: skip


@_FUZZ_SETTINGS
@given(text=st.one_of(_mutated(), st.text(max_size=200)))
def test_random_and_mutated_toml_only_ever_raise_a_located_scenario_error(text):
    try:
        parse_scenario(text, "fuzz.toml")
    except ScenarioError as exc:
        _assert_located(exc, text)


_SCENARIO = load_scenario("static-ahead-20m")
_KEYS = ["camera.delay_s", "camera.rate_hz", "gains.k_v", "gains.zz", "wind.mean_m_s",
         "target.motion", "duration_s", "name", "optics.f", "sim.physics_rate_hz", ""]  # fmt: skip


@_FUZZ_SETTINGS
@given(
    items=st.lists(
        st.one_of(
            st.text(max_size=30),
            st.builds(
                lambda k, v: f"{k}={v}",
                st.sampled_from(_KEYS),
                st.one_of(
                    st.text(max_size=10),
                    st.sampled_from(
                        ["0", "-1", "1e9", "nan", "[1,2,3]", '"cv"', "true", "abc", "[", "7"]
                    ),
                ),
            ),
        ),
        max_size=4,
    )
)
def test_random_set_strings_only_ever_raise_a_located_scenario_error(items):
    try:
        with_overrides(_SCENARIO, parse_overrides(items))
    except ScenarioError as exc:
        assert exc.problems and str(exc)
        for p in exc.problems:
            assert p.key is not None or "expected SECTION.KEY=VALUE" in p.message, p


# ----------------------------------------------------------------------------- sortie logs
@pytest.fixture(scope="module")
def log_file(tmp_path_factory):
    from groundstation.recording.writer import SortieRecorder
    from groundstation.sim.simulation import Simulation

    rec = SortieRecorder(tmp_path_factory.mktemp("log"))
    sim = Simulation(  # rendered: camera frames make several 256 kB chunks
        load_scenario("cv-top-to-bottom"), camera_mode="rendered", keep_records=False,
        observers=[rec],
    )  # fmt: skip
    sim.run()
    assert rec.closed and rec.error is None
    return rec.path


def test_damaged_logs_say_what_is_wrong_and_what_was_recovered(log_file, tmp_path, capsys):
    data = log_file.read_bytes()
    old = time.time() - 60
    (tmp_path / "truncated.mcap").write_bytes(data[: len(data) // 2])
    garbled = bytearray(data)
    mid = len(data) // 2
    garbled[mid : mid + 2000] = bytes((i * 97 + 13) % 256 for i in range(2000))
    (tmp_path / "garbled.mcap").write_bytes(bytes(garbled))
    (tmp_path / "empty.mcap").write_bytes(b"")
    (tmp_path / "wrong-magic.mcap").write_bytes(b"PK\x03\x04" + data[8:])
    (tmp_path / "cut-in-magic.mcap").write_bytes(data[:4])
    for p in tmp_path.iterdir():
        os.utime(p, (old, old))  # written a minute ago: finished, not being written
    (tmp_path / "being-written.mcap").write_bytes(data[: len(data) // 3])  # just now
    (tmp_path / "ok.mcap").write_bytes(data)

    trunc = inspect_log(tmp_path / "truncated.mcap")
    assert trunc.status == "truncated" and trunc.messages > 0
    n_trunc = len(list(iter_messages(tmp_path / "truncated.mcap")))
    assert trunc.problem.startswith("truncated at t = ")
    assert f"s, {trunc.messages} messages recovered (the file ends early" in trunc.problem
    assert n_trunc == trunc.messages
    garb = inspect_log(tmp_path / "garbled.mcap")
    assert garb.status == "damaged" and garb.problem.startswith("damaged near byte ")
    assert f"{garb.messages} messages recovered" in garb.problem and garb.messages > 0
    live = inspect_log(tmp_path / "being-written.mcap")
    assert live.status == "truncated" and "so far: still being written" in live.problem
    for name, needle in (
        ("empty.mcap", "empty (0 bytes), nothing to recover"),
        ("wrong-magic.mcap", "starts with b'PK\\x03\\x04"),
        ("cut-in-magic.mcap", "cut after 4 bytes, inside the MCAP magic"),
    ):
        with pytest.raises(LogError, match="not an MCAP file") as exc:
            inspect_log(tmp_path / name)
        assert needle in str(exc.value)

    listed = {r["name"]: r for r in LogIndex(tmp_path).list()}  # one call, never fails whole
    assert {k: v["status"] for k, v in listed.items()} == {
        "truncated.mcap": "truncated",
        "garbled.mcap": "damaged",
        "empty.mcap": "not_mcap",
        "wrong-magic.mcap": "not_mcap",
        "cut-in-magic.mcap": "not_mcap",
        "being-written.mcap": "truncated",
        "ok.mcap": "ok",
    }
    assert "nothing to recover" in listed["empty.mcap"]["problem"]

    code, out, err = _run(capsys, "replay", str(tmp_path / "truncated.mcap"), "--json")
    assert code == 0 and json.loads(out)["problem"] == trunc.problem
    code, out, err = _run(capsys, "replay", str(tmp_path / "empty.mcap"))
    assert code == 2 and "empty (0 bytes)" in err and "Traceback" not in err


def test_replay_json_metadata_are_values_not_strings(log_file, capsys):
    code, out, _ = _run(capsys, "replay", str(log_file), "--json")
    assert code == 0
    meta = json.loads(out)["metadata"]
    assert meta["sortie"]["seed"] == 0 and meta["sortie"]["law"] == "png"
    assert meta["sortie"]["gains"]["k_a"] == 2.0  # an object, not a JSON string
    assert meta["sortie"]["scenario"] == "cv-top-to-bottom"
    # the outcome of seed 0 with realistic sensors is not this test's business: its type is
    assert meta["outcome"]["outcome"] in {"HIT", "MISS"}
    assert isinstance(meta["outcome"]["miss_m"], float)


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["run", "--camera", "0", "--rate", "0"], "argument --rate: must be a number of Hz > 0"),
        (["run", "--camera", "0", "--rate", "nan"], "argument --rate: must be a number of Hz"),
        (["run", "--camera", "0", "--duration", "-1"], "argument --duration: must be a number"),
    ],
)
def test_onboard_options_are_checked_too(capsys, argv, needle):
    from onboard.cli import main as onboard_main

    with pytest.raises(SystemExit) as exc:
        onboard_main(argv)
    err = capsys.readouterr().err
    assert exc.value.code == 2 and needle in err and "Traceback" not in err


def test_a_cut_anywhere_is_truncated_not_damaged(log_file, tmp_path):
    """Wherever a copy or a crash cuts the file (inside a record's header, its body, a chunk),
    the log reads as truncated, never as corrupt bytes."""
    data = log_file.read_bytes()
    cut = tmp_path / "cut.mcap"
    for k in range(1, 60):
        at = 8 + (len(data) - 8) * k // 61 + k % 9  # spread over the file, odd offsets too
        cut.write_bytes(data[:at])
        info = inspect_log(cut)
        assert info.status == "truncated", (at, info.problem)
