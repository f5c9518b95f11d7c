"""``--backend ray``: sorties as Ray tasks on a private local Ray give the process pool's
results; a missing Ray or a bad address is one clear line and exit 2."""

import json
import os
import sys

import pytest

from groundstation.campaigns import LocalPoolRunner, build_jobs
from groundstation.campaigns.ray_runner import RayRunner, make_runner, ray_available
from groundstation.cli import main

from .cli_support import run_cli

needs_ray = pytest.mark.skipif(
    not ray_available() and not os.environ.get("CI"),
    reason="ray is not installed (pip install '.[cluster]'); CI installs it and runs this",
)


# two sorties, one per law: what the Ray tests fly, and the process pool's outcomes of them
ARGS = ["static", "--n", "1", "--laws", "png,pg", "--seed", "3"]


def _jobs():
    return build_jobs("static", 1, ("png", "pg"), seed=3)


@pytest.fixture(scope="module")
def pool_outcomes():
    return LocalPoolRunner(1).run(_jobs())


@needs_ray
def test_ray_campaign_gives_the_process_pool_results(tmp_path, capfd, pool_outcomes):
    out = tmp_path / "ray"
    args = ["campaign", *ARGS, "--json", "--backend", "ray", "--workers", "2", "--out", str(out)]
    code, stdout, err = run_cli(main, args, capfd)  # file descriptors: Ray's processes' too
    assert code == 0, err
    meta = json.loads(stdout)["meta"]  # stdout is the JSON alone: no Ray chatter
    assert meta["backend"] == "RayRunner" and meta["workers"] == 2 and meta["sorties"] == 2
    ray_sorties = json.loads((out / "results.json").read_text())["sorties"]
    assert len(ray_sorties) == len(pool_outcomes) == 2
    for s, o in zip(ray_sorties, pool_outcomes, strict=True):
        assert s == {"labels": o.labels, **o.result}  # bit for bit, in job order


@needs_ray
def test_one_local_ray_serves_several_runs_and_is_loopback_only(pool_outcomes):
    jobs = _jobs()
    with RayRunner(workers=1) as runner:
        import ray

        node_ip = ray.util.get_node_ip_address()
        first = runner.run(jobs)
        second = runner.run(jobs[::-1])  # submission order does not matter either
        assert ray.is_initialized()
    assert not ray.is_initialized()  # the runner stopped the Ray it started
    assert node_ip == "127.0.0.1"
    expected = [o.result for o in pool_outcomes]
    assert [o.result for o in first] == [o.result for o in second] == expected
    assert [o.trace for o in first] == [o.trace for o in pool_outcomes]


def test_missing_ray_is_one_line_and_exit_2(tmp_path, capsys, monkeypatch):
    out = tmp_path / "x"
    monkeypatch.setitem(sys.modules, "ray", None)  # as if ray were not installed
    argv = ["campaign", "static", "--backend", "ray", "--out", str(out)]
    code, _, err = run_cli(main, argv, capsys)
    assert code == 2
    assert err.strip().splitlines() == [
        "groundstation: error: --backend ray needs Ray, which is not installed: "
        "pip install 'peregrine[cluster]'"
    ]
    assert not out.exists()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--ray-address", "127.0.0.1:6379"], "--ray-address needs --backend ray"),
        (["--backend", "spark"], "invalid choice: 'spark'"),
        (["--workers", "0"], "argument --workers: must be an integer >= 1"),
        (
            ["--backend", "ray", "--ray-address", "127.0.0.1:1", "--workers", "2"],
            "a Ray cluster (127.0.0.1:1) schedules on all its CPUs",
        ),
        (["--backend", "ray", "--ray-address", "nohost"], "expected HOST:PORT"),
        (["--backend", "ray", "--ray-address", "127.0.0.1:1"], "cannot reach the Ray cluster"),
    ],
)
def test_bad_backend_options_are_refused_before_work(args, message, tmp_path, capsys):
    if "ray" in args and not ray_available():
        pytest.skip("ray is not installed")
    args = ["campaign", "static", "--n", "1", *args, "--out", str(tmp_path / "x")]
    code, _, err = run_cli(main, args, capsys)
    assert code == 2 and message in err and "Traceback" not in err
    assert not (tmp_path / "x").exists()


def test_process_backend_is_the_default():
    assert isinstance(make_runner(), LocalPoolRunner)
