"""Sortie recording to MCAP and reading it back: channels, schemas, metadata, damaged files,
never overwriting, a full disk."""

import json
import random
import subprocess
import sys
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader

from groundstation.cli import main
from groundstation.recording.reader import LogError, LogIndex, inspect_log, iter_messages
from groundstation.recording.writer import SortieRecorder, open_new_log
from groundstation.scenario import load_scenario
from groundstation.sim.simulation import Simulation
from onboard.channels.schemas import CHANNELS

from .cli_support import run_cli


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    d = tmp_path_factory.mktemp("logs")
    rec = SortieRecorder(d)
    sim = Simulation(
        load_scenario("cv-top-to-bottom"), camera_mode="rendered", keep_records=False,
        observers=[rec],
    )  # fmt: skip
    result = sim.run()
    assert rec.closed and rec.error is None
    return rec.path, result


def test_round_trip_every_channel_schema_and_metadata(recorded):
    path, result = recorded
    assert path.name.endswith("_cv-top-to-bottom_png.mcap")
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        schemas = {ch.topic: summary.schemas[ch.schema_id].name for ch in summary.channels.values()}
        assert schemas == dict(CHANNELS)
        assert all(ch.message_encoding == "json" for ch in summary.channels.values())
        assert all(s.encoding == "jsonschema" for s in summary.schemas.values())
        counts = summary.statistics.channel_message_counts
        topics = {summary.channels[cid].topic: n for cid, n in counts.items()}
        for topic, _ in CHANNELS:
            assert topics.get(topic, 0) > 0, topic
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
        assert meta["sortie"]["scenario"] == "cv-top-to-bottom"
        assert meta["sortie"]["law"] == "png" and meta["sortie"]["camera"] == "rendered"
        assert json.loads(meta["sortie"]["gains"])["k_a"] == 2.0
        assert "peregrine" in meta["sortie"]["software_version"]
        assert json.loads(meta["outcome"]["outcome"]) == result.outcome
        assert json.loads(meta["outcome"]["miss_m"]) == pytest.approx(result.miss_m, abs=1e-6)
        atts = list(reader.iter_attachments())
        assert atts[0].name == "scenario.toml" and b'name = "cv-top-to-bottom"' in atts[0].data
        # log times are the sortie's own clock: from 0 to the end of the sortie
        times = [m.log_time for _, _, m in reader.iter_messages()]
        assert min(times) == 0 and max(times) / 1e9 == pytest.approx(result.sim_time_s, abs=0.05)
    msgs = {}
    for topic, _t, m in iter_messages(path):
        msgs.setdefault(topic, m)
    assert set(msgs["/world/vehicle"]["pose"]) == {"position", "orientation"}
    assert msgs["/tf"]["transforms"][1]["child_frame_id"] == "camera"
    assert msgs["/camera/image"]["format"] == "jpeg" and len(msgs["/camera/image"]["data"]) > 1000
    assert msgs["/camera/calibration"]["K"][0] == pytest.approx(320.0)
    assert msgs["/events"]["message"].startswith("sortie start")
    assert "los_elev_rad" in msgs["/control"] and "cov_diag" in msgs["/dkf"]


def test_events_tell_the_story(recorded):
    path, _ = recorded
    events = [m["message"] for topic, _t, m in iter_messages(path, ["/events"])]
    assert events[0].startswith("sortie start")
    assert "target acquired" in events
    assert events[-1].startswith(("outcome HIT", "outcome MISS"))  # seed 0's, realistic sensors


def test_index_seek_reads_a_window(recorded):
    path, _ = recorded
    window = list(iter_messages(path, ["/control"], 2.0, 3.0))
    assert 15 <= len(window) <= 25  # 20 Hz
    assert all(2.0 <= t < 3.0 for _, t, _ in window)


def _damaged_copies(path: Path, d: Path):
    data = path.read_bytes()
    trunc = d / "truncated.mcap"
    trunc.write_bytes(data[: len(data) // 2])
    rng = random.Random(7)
    garbled = bytearray(data)
    mid = len(garbled) // 2
    garbled[mid : mid + 3000] = bytes(rng.randrange(256) for _ in range(3000))
    garb = d / "garbage.mcap"
    garb.write_bytes(bytes(garbled))
    return trunc, garb


def test_truncated_and_garbled_files_have_a_status_and_replay_up_to_the_damage(recorded, tmp_path):
    path, _ = recorded
    trunc, garb = _damaged_copies(path, tmp_path)
    full = sum(1 for _ in iter_messages(path))
    for f, status in ((trunc, "truncated"), (garb, "damaged")):
        info = inspect_log(f)
        assert info.status == status and info.problem
        assert info.scenario == "cv-top-to-bottom"  # the metadata at the start survives
        msgs = list(iter_messages(f))
        assert 0 < len(msgs) < full
        times = [t for _, t, _ in msgs]
        assert times == sorted(times)  # nothing replayed twice
    listed = {r["name"]: r["status"] for r in LogIndex(tmp_path).list()}
    assert listed == {"truncated.mcap": "truncated", "garbage.mcap": "damaged"}


def test_non_mcap_refused_and_names_cannot_leave_the_folder(tmp_path, capsys):
    (tmp_path / "notes.mcap").write_text("not a log")
    with pytest.raises(LogError, match="not an MCAP file"):
        inspect_log(tmp_path / "notes.mcap")
    assert LogIndex(tmp_path).list()[0]["status"] == "not_mcap"
    index = LogIndex(tmp_path / "logs")
    for bad in (
        "../secret.mcap",
        "..",
        "/etc/passwd",
        "a/../../b.mcap",
        "a/.hidden/b.mcap",
        ".hidden.mcap",
        "x.txt",
        "x\x00.mcap",
    ):
        with pytest.raises(LogError):
            index.resolve(bad)
    # a campaign's folder inside the log folder is fine: names are paths in it
    root = (tmp_path / "logs").resolve()
    assert index.resolve("static-n2/a.mcap") == root / "static-n2" / "a.mcap"
    code, _, err = run_cli(main, ["replay", str(tmp_path / "notes.mcap")], capsys)
    assert code == 2 and "not an MCAP file" in err and "Traceback" not in err


def test_never_overwrites(tmp_path):
    paths = []
    for _ in range(3):
        p, f = open_new_log(tmp_path, "same", "png")
        f.write(b"x")
        f.close()
        paths.append(p)
    assert len(set(paths)) == 3 and all(p.read_bytes() == b"x" for p in paths)


def test_full_disk_ends_recording_not_sortie(tmp_path, monkeypatch):
    monkeypatch.setenv("PEREGRINE_RECORD_IN_PROCESS", "1")  # to reach the file object
    rec = SortieRecorder(tmp_path)
    sim = Simulation(load_scenario("static-ahead-20m"), keep_records=False, observers=[rec])
    real_write = rec._sink.file.write
    calls = {"n": 0}

    def write(data):
        calls["n"] += 1
        if calls["n"] > 2:
            raise OSError(28, "No space left on device")
        return real_write(data)

    monkeypatch.setattr(rec._sink.file, "write", write, raising=False)
    result = sim.run()
    assert result.outcome == "HIT"  # the sortie flew on
    assert rec.closed and "No space left on device" in rec.error


def test_full_disk_in_the_recording_process_ends_recording_not_sortie(tmp_path, monkeypatch):
    from groundstation.recording import writer

    full = tmp_path / "full.mcap"
    full.symlink_to("/dev/full")  # every write: ENOSPC
    monkeypatch.setattr(writer, "open_new_log", lambda *_a: (full, open(full, "wb")))  # noqa: SIM115
    rec = SortieRecorder(tmp_path)
    sim = Simulation(load_scenario("static-ahead-20m"), keep_records=False, observers=[rec])
    assert type(rec._sink).__name__ == "ProcessSink"
    result = sim.run()
    assert result.outcome == "HIT"  # the sortie flew on
    assert rec.closed and "No space left on device" in rec.error


def test_a_crashed_sortie_leaves_a_complete_file(tmp_path):
    """The process flying the sortie dies mid-flight; the recording process finishes the file
    (summary and index written), marked INCOMPLETE."""
    code = (
        "import os, sys\n"
        "from groundstation.scenario import load_scenario\n"
        "from groundstation.sim.simulation import Simulation\n"
        "from groundstation.recording.writer import SortieRecorder\n"
        f"rec = SortieRecorder({str(tmp_path)!r})\n"
        "sim = Simulation(load_scenario('cv-top-to-bottom'), keep_records=False,\n"
        "                 observers=[rec])\n"
        "for _ in range(1200):\n"
        "    sim.step()\n"
        "rec._sink._flush()\n"
        "os._exit(3)\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], timeout=120)
    assert proc.returncode == 3
    (path,) = tmp_path.glob("*.mcap")

    def finished() -> bool:
        try:
            return inspect_log(path).status == "ok"
        except LogError:  # still being written by the recording process
            return False

    deadline = time.monotonic() + 10.0
    while not finished() and time.monotonic() < deadline:
        time.sleep(0.1)  # the recording process finishes the file when its input ends
    info = inspect_log(path)
    assert info.status == "ok" and info.outcome == "INCOMPLETE"
    assert sum(1 for t, _, _ in iter_messages(path) if t == "/control") >= 30


def test_replay_cli_json(recorded, capsys):
    path, result = recorded
    code, out, err = run_cli(main, ["replay", str(path), "--json"], capsys)
    assert code == 0, err
    d = json.loads(out)
    assert d["status"] == "ok" and d["outcome"] == result.outcome
    assert d["topics"]["/control"] > 50 and d["events"][-1]["message"].startswith("outcome")


def test_sortie_cli_log_flag(tmp_path, capsys):
    argv = ["sortie", "static-ahead-20m", "--log", str(tmp_path), "--json"]
    code, out, err = run_cli(main, argv, capsys)
    assert code == 0, err
    log = Path(json.loads(out)["log"])
    assert log.parent == tmp_path and inspect_log(log).status == "ok"


def test_a_changed_scenario_is_recorded_as_flown(tmp_path):
    # campaigns move targets and --set changes values: the recording must carry the scenario
    # that flew, or re-flying it from the dashboard would fly another sortie
    from groundstation.recording.reader import scenario_attachment
    from groundstation.scenario import parse_scenario, with_overrides

    flown = with_overrides(
        load_scenario("static-ahead-20m"),
        {"target.position_m": [3.0, 18.0, 11.0], "gains.k_v": 50, "camera.noise_px": 0.5},
    )
    rec = SortieRecorder(tmp_path)
    Simulation(flown, law="pg", keep_records=False, observers=[rec]).run()
    back = parse_scenario(scenario_attachment(rec.path))
    assert back.target.position_m == (3.0, 18.0, 11.0)
    assert back.gains["k_v"] == 50.0 and back.camera.noise_px == 0.5
