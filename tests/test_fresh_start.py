"""A fresh install starts at once: the single-sortie commands run the kernels as Python (no
compiler on the first run), the batch commands ask for the JIT, and the environment wins.

Each command runs as the installed console script would, in a subprocess with an empty numba
cache (``NUMBA_CACHE_DIR``: what a fresh install has) and no ``PEREGRINE_JIT``. The start-up
times themselves are measured in docs/kernels.md, not asserted here."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from onboard import jit

ROOT = Path(__file__).resolve().parents[1]


def _fresh_env(cache: Path, **extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k != jit.ENV}
    env["NUMBA_CACHE_DIR"] = str(cache)
    env.update(extra)
    return env


def _script(name: str) -> list[str]:
    """The installed console script ``name`` (beside this interpreter), else its module."""
    exe = Path(sys.executable).parent / name
    if exe.exists():
        return [str(exe)]
    found = shutil.which(name)
    return [found] if found else [sys.executable, "-m", f"{name}.cli"]


def test_first_sortie_after_install_hits_without_compiling(tmp_path):
    out = subprocess.run(
        [*_script("groundstation"), "sortie", "static-ahead-20m"],
        env=_fresh_env(tmp_path),
        capture_output=True,
        text=True,
        timeout=600,
        cwd=tmp_path,
    )
    assert out.returncode == 0, out.stderr
    assert "static-ahead-20m: HIT" in out.stdout
    assert "compiling" not in out.stderr.lower(), out.stderr
    assert not any(tmp_path.rglob("*.nbi")), "a numba cache was written: something compiled"


_MODES = """
import sys
from onboard import jit
if sys.argv[1] == "batch":
    jit.use_jit()
import onboard.loop
print(jit.ENABLED, len(jit.KERNELS), all(hasattr(k, "py_func") for k in jit.KERNELS))
"""


@pytest.mark.parametrize(
    ("env_value", "command", "expected"),
    [
        (None, "single", "False"),  # sortie, serve, onboard run: Python
        ("0", "batch", "False"),  # the environment wins over a batch command
    ],
)
def test_jit_mode_is_chosen_before_the_kernels_are_defined(tmp_path, env_value, command, expected):
    extra = {} if env_value is None else {jit.ENV: env_value}
    out = subprocess.run(
        [sys.executable, "-c", _MODES, command],
        env=_fresh_env(tmp_path, **extra),
        capture_output=True,
        text=True,
        timeout=300,
        cwd=ROOT,
    )
    assert out.returncode == 0, out.stderr
    enabled, count, compiled = out.stdout.split()
    assert enabled == expected
    assert int(count) >= 40  # the onboard kernels
    assert compiled == expected


def test_use_jit_after_kernels_were_defined_refuses(monkeypatch):
    """Switching on after a kernel module was imported as Python would mix the two modes."""
    monkeypatch.delenv(jit.ENV, raising=False)
    monkeypatch.setattr(jit, "ENABLED", False)
    monkeypatch.setattr(jit, "KERNELS", [len])
    with pytest.raises(RuntimeError, match="before importing them"):
        jit.use_jit()
    monkeypatch.setenv(jit.ENV, "0")  # told to stay Python: nothing to refuse
    monkeypatch.setattr(jit, "KERNELS", [len])
    assert jit.use_jit() is False


def test_batch_commands_ask_for_the_jit_and_pass_it_to_their_workers(monkeypatch):
    """``campaign``, ``tune`` and ``bench`` call :func:`onboard.jit.use_jit` before they import
    the simulator; it sets ``PEREGRINE_JIT=1`` for the processes they start (the pool's
    forkserver, Ray's workers)."""
    from groundstation import cli

    assert set(cli._JIT_COMMANDS) == {"campaign", "tune", "bench"}
    monkeypatch.delenv(jit.ENV, raising=False)
    monkeypatch.setattr(jit, "KERNELS", [])
    monkeypatch.setattr(jit, "ENABLED", False)
    assert jit.use_jit() is True
    assert os.environ[jit.ENV] == "1"


def _probe(_: int) -> bool:
    return "groundstation.sim.simulation" in sys.modules


def test_campaign_workers_fork_from_a_server_that_has_the_simulator():
    """A worker needs no import of its own: it is a fork of the pool's server, which imported
    the simulator (and loaded its kernels) once."""
    from concurrent.futures import ProcessPoolExecutor

    from groundstation import cli
    from groundstation.campaigns.pool import pool_context, start_pool_server

    args = cli._build_parser().parse_args
    assert cli._makes_pool(args(["campaign", "static"]))
    assert not cli._makes_pool(args(["campaign", "static", "--backend", "ray"]))
    assert cli._makes_pool(args(["bench", "--campaigns"]))
    assert not cli._makes_pool(args(["bench"]))
    assert not cli._makes_pool(args(["sortie", "static-ahead-20m"]))
    assert start_pool_server(1) is False  # one worker: no pool
    ctx = pool_context()
    if ctx.get_start_method() != "forkserver":
        pytest.skip("no forkserver on this platform")
    assert start_pool_server(2) is True
    with ProcessPoolExecutor(2, mp_context=ctx) as pool:
        assert list(pool.map(_probe, range(2))) == [True, True]
