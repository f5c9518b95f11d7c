"""``--backend ray``: sorties as Ray tasks on a private local Ray give the process pool's
results; a missing Ray or a bad address is one clear line and exit 2."""

import json
import os
import subprocess
import sys

import pytest

from groundstation.campaigns import LocalPoolRunner, build_jobs
from groundstation.campaigns.ray_runner import RayRunner, make_runner, ray_available

needs_ray = pytest.mark.skipif(
    not ray_available() and not os.environ.get("CI"),
    reason="ray is not installed (pip install '.[cluster]'); CI installs it and runs this",
)


@needs_ray
def test_ray_campaign_gives_the_process_pool_results(tmp_path):
    out = tmp_path / "ray"
    args = ["campaign", "moving", "--n", "1", "--laws", "png,pg", "--seed", "3", "--json"]
    args += ["--backend", "ray", "--workers", "2", "--out", str(out)]
    r = subprocess.run(
        [sys.executable, "-m", "groundstation", *args],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 0, r.stderr
    meta = json.loads(r.stdout)["meta"]  # stdout is the JSON alone: no Ray chatter
    assert meta["backend"] == "RayRunner" and meta["workers"] == 2 and meta["sorties"] == 6
    ray_sorties = json.loads((out / "results.json").read_text())["sorties"]
    pool = LocalPoolRunner(2).run(build_jobs("moving", 1, ("png", "pg"), seed=3))
    assert len(ray_sorties) == len(pool) == 6
    for s, o in zip(ray_sorties, pool, strict=True):
        assert s == {"labels": o.labels, **o.result}  # bit for bit, in job order


@needs_ray
def test_one_local_ray_serves_several_runs_and_is_loopback_only():
    jobs = build_jobs("static", 2, ("png",), seed=7)
    expected = LocalPoolRunner(1).run(jobs)
    with RayRunner(workers=1) as runner:
        import ray

        node_ip = ray.util.get_node_ip_address()
        first = runner.run(jobs)
        second = runner.run(jobs[::-1])  # submission order does not matter either
        assert ray.is_initialized()
    assert not ray.is_initialized()  # the runner stopped the Ray it started
    assert node_ip == "127.0.0.1"
    assert [o.result for o in first] == [o.result for o in second] == [o.result for o in expected]
    assert [o.trace for o in first] == [o.trace for o in expected]


def test_missing_ray_is_one_line_and_exit_2(tmp_path):
    out = tmp_path / "x"
    code = (
        "import sys; sys.modules['ray'] = None\n"  # as if ray were not installed
        "from groundstation.cli import main\n"
        f"sys.exit(main(['campaign', 'static', '--backend', 'ray', '--out', {str(out)!r}]))"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 2
    assert r.stderr.strip().splitlines() == [
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
def test_bad_backend_options_are_refused_before_work(args, message, tmp_path):
    if "ray" in args and not ray_available():
        pytest.skip("ray is not installed")
    args = ["campaign", "static", "--n", "1", *args, "--out", str(tmp_path / "x")]
    r = subprocess.run(
        [sys.executable, "-m", "groundstation", *args],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 2 and message in r.stderr and "Traceback" not in r.stderr
    assert not (tmp_path / "x").exists()


def test_process_backend_is_the_default():
    assert isinstance(make_runner(), LocalPoolRunner)
