"""The dashboard's gain studies: the studies `groundstation tune` stored are
listed with their trials and best-so-far curve, and any trial's gains fly in one click beside
the defaults (the defaults' sortie recorded and overlaid), behind the token."""

import time
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from groundstation.campaigns.tune import GainRange, TuneDefinition, default_storage_url
from onboard.gains import Gains

optuna = pytest.importorskip("optuna")

TRIALS = [  # (k_v, K_y, loss, success rate)
    ({"k_v": 2.0, "K_y": 3.0}, 0.40, 0.6),
    ({"k_v": 4.0, "K_y": 2.0}, 0.55, 0.4),
    ({"k_v": 6.0, "K_y": 4.5}, 0.10, 1.0),
    ({"k_v": 3.0, "K_y": 3.5}, 0.30, 0.8),
]


def make_study(data_dir: Path, name: str = "static-try") -> None:
    """A study as `groundstation tune static-ahead-20m --gains k_v,K_y` leaves it (made here
    without flying: the figures are given)."""
    defn = TuneDefinition(
        target="static-ahead-20m",
        space=(GainRange("k_v", 0.5, 20.0), GainRange("K_y", 0.5, 8.0)),
        n=1,
    )
    study = optuna.create_study(
        study_name=name, storage=default_storage_url(data_dir), direction="minimize"
    )
    study.set_user_attr("definition", defn.to_json_dict())
    dists = {
        "k_v": optuna.distributions.FloatDistribution(0.5, 20.0),
        "K_y": optuna.distributions.FloatDistribution(0.5, 8.0),
    }
    for params, loss, success in TRIALS:
        study.add_trial(
            optuna.trial.create_trial(
                params=params,
                distributions=dists,
                value=loss,
                user_attrs={"success_rate": success, "cep_m": loss, "n": 1},
            )
        )
    study.add_trial(optuna.trial.create_trial(state=optuna.trial.TrialState.FAIL))


def test_no_study_lists_nothing_and_creates_nothing(client, tmp_path):
    assert client.get("/api/studies").json() == []
    assert not (tmp_path / "studies.db").exists()
    assert client.get("/api/studies/nope").status_code == 404


def test_studies_trials_and_best_so_far(client, tmp_path):
    make_study(tmp_path)
    (s,) = client.get("/api/studies").json()
    assert s["name"] == "static-try" and s["trials"] == 5 and s["target"] == "static-ahead-20m"
    assert s["best_trial"] == 2 and s["best_value"] == pytest.approx(0.10)
    assert s["gains"] == ["k_v", "K_y"]
    d = client.get("/api/studies/static-try").json()
    assert [t["number"] for t in d["trials"]] == [0, 1, 2, 3, 4]
    assert d["trials"][2]["params"] == {"k_v": 6.0, "K_y": 4.5}
    assert d["trials"][2]["figures"]["success_rate"] == 1.0
    assert d["trials"][4]["state"] == "FAIL" and d["trials"][4]["value"] is None
    assert d["best_so_far"] == pytest.approx([0.40, 0.40, 0.10, 0.10, 0.10])


def test_flying_a_trial_flies_its_gains_beside_the_defaults(client, gs, tmp_path):
    make_study(tmp_path)
    # behind the token like every vehicle-changing action
    with TestClient(gs.app, base_url="http://127.0.0.1") as anon:
        assert anon.post("/api/studies/static-try/trials/2/fly", json={}).status_code == 401
    assert client.post("/api/studies/static-try/trials/4/fly", json={}).status_code == 409
    assert client.post("/api/studies/static-try/trials/9/fly", json={}).status_code == 404
    bad = client.post("/api/studies/static-try/trials/2/fly", json={"speed": "3"})
    assert bad.status_code == 422 and client.get("/api/logs").json() == []  # nothing flown
    st = client.post("/api/studies/static-try/trials/2/fly", json={"speed": "max"}).json()
    assert st["gains_source"] == "study static-try trial #2"
    assert st["scenario"] == "static-ahead-20m" and st["law"] == "png" and st["speed"] == "max"
    gains = client.get("/api/gains").json()
    flown = gains.get("values", gains)
    assert flown["k_v"] == 6.0 and flown["K_y"] == 4.5
    # the overlay: the same sortie flown with the defaults, recorded, named in the status
    cmp = st["compare"]
    defaults = Gains().to_dict()
    assert cmp["scenario"] == "static-ahead-20m" and cmp["law"] == "png"
    assert cmp["gains"]["k_v"] == defaults["k_v"] and cmp["gains"]["K_y"] == defaults["K_y"]
    deadline = time.monotonic() + 30
    while client.get("/api/status").json()["state"] != "finished":
        assert time.monotonic() < deadline
        time.sleep(0.05)
    logs = {r["name"]: r for r in client.get("/api/logs").json()}
    assert cmp["file"] in logs and len(logs) == 2  # the defaults' sortie and the trial's
