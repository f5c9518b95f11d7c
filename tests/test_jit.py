"""onboard.jit: a compiled kernel is its Python source, operation for operation.

A whole set of sorties flown with every kernel compiled (this process) and with
``PEREGRINE_JIT=0`` (the same functions run as Python, in a subprocess) must agree to the
bit, and nothing may compile after import (a vehicle never compiles mid-sortie)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from onboard import jit
from tests.speed_reference import CASES, compute

ROOT = Path(__file__).resolve().parents[1]
# static, moving, windy/tethered, takeoff, all three laws, and the rendered camera
BIT_CASES = [CASES[0], CASES[1], CASES[3], CASES[4], CASES[7], CASES[8]]

_SCRIPT = """
import json, sys
from onboard import jit
from tests.speed_reference import compute
assert not jit.ENABLED
cases = json.loads(sys.argv[1])
print(json.dumps([compute(tuple(c)) for c in cases]))
"""


def test_disabled_kernel_is_the_function_itself(monkeypatch):
    monkeypatch.setattr(jit, "ENABLED", False)
    monkeypatch.setattr(jit, "KERNELS", [])

    def add(a: float, b: float) -> float:
        return a + b

    assert jit.kernel("float64(float64, float64)")(add) is add


@pytest.mark.skipif(not jit.ENABLED, reason="PEREGRINE_JIT=0: nothing is compiled")
def test_compiled_kernel_equals_its_source_bit_for_bit(monkeypatch):
    monkeypatch.setattr(jit, "KERNELS", [])

    # a sum that depends on the order of its operations: no reassociation, no FMA
    def dot_then_scale(a: np.ndarray, b: np.ndarray, k: float) -> float:
        s = 0.0
        for i in range(a.shape[0]):
            s += a[i] * b[i]
        return s * k + a[0] * b[-1]

    k = jit.kernel("float64(float64[::1], float64[::1], float64)")(dot_then_scale)
    rng = np.random.default_rng(9)
    for _ in range(200):
        a, b = rng.normal(size=17) * 1e3, rng.normal(size=17) * 1e-3
        c = float(rng.normal())
        assert k(a, b, c) == dot_then_scale(a, b, c)


@pytest.mark.skipif(not jit.ENABLED, reason="PEREGRINE_JIT=0: nothing is compiled")
def test_sorties_fly_the_same_compiled_and_as_python():
    compiled = [compute(c) for c in BIT_CASES]
    signatures_before = [len(getattr(k, "signatures", ())) for k in jit.KERNELS]
    env = dict(os.environ, PEREGRINE_JIT="0")
    proc = subprocess.run(
        [sys.executable, "-c", _SCRIPT, json.dumps([list(c) for c in BIT_CASES])],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
        check=True,
    )
    as_python = json.loads(proc.stdout)
    for case, got, want in zip(BIT_CASES, compiled, as_python, strict=True):
        assert got == want, case  # exact: floats round-trip through JSON
    # every kernel was compiled at import for its signature; flying compiled nothing more
    assert [len(getattr(k, "signatures", ())) for k in jit.KERNELS] == signatures_before
    for k in jit.KERNELS:
        assert len(k.signatures) >= 1, k


def _env_with_cache_in(tmp_path) -> dict[str, str]:
    """A subprocess's environment: modules from ``tmp_path`` and the project, numba's cache in
    ``tmp_path/cache``."""
    env = dict(os.environ, PYTHONPATH=f"{tmp_path}{os.pathsep}{ROOT}")
    env["NUMBA_CACHE_DIR"] = str(tmp_path / "cache")
    return env


@pytest.mark.skipif(not jit.ENABLED, reason="PEREGRINE_JIT=0: nothing is compiled")
def test_a_cold_cache_says_it_is_compiling_once_and_a_warm_one_is_silent(tmp_path):
    (tmp_path / "tiny_kernels.py").write_text(
        "from onboard.jit import kernel\n"
        "@kernel('float64(float64)')\n"
        "def twice(x):\n    return 2.0 * x\n"
        "@kernel('float64(float64)')\n"
        "def thrice(x):\n    return 3.0 * x\n"
    )
    env = _env_with_cache_in(tmp_path)
    run = [sys.executable, "-c", "import tiny_kernels as k; print(k.twice(2.0) + k.thrice(1.0))"]
    cold = subprocess.run(run, env=env, capture_output=True, text=True, check=True, timeout=300)
    warm = subprocess.run(run, env=env, capture_output=True, text=True, check=True, timeout=300)
    assert cold.stdout.strip() == warm.stdout.strip() == "7.0"
    assert cold.stderr.count("compiling the numba kernels") == 1, cold.stderr
    assert "compiling" not in warm.stderr, warm.stderr


@pytest.mark.skipif(not jit.ENABLED, reason="PEREGRINE_JIT=0: nothing is compiled")
def test_no_writable_cache_anywhere_compiles_at_every_start_instead_of_failing(tmp_path):
    # a read-only image: the module's __pycache__ and the per-user cache cannot be made (here
    # files stand where numba would make directories: as root a chmod would not stop it)
    pkg = tmp_path / "ro_pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "__pycache__").write_text("")
    (pkg / "kernels.py").write_text(
        "from onboard.jit import kernel\n"
        "@kernel('float64(float64)')\n"
        "def twice(x):\n    return 2.0 * x\n"
    )
    home = tmp_path / "home_is_a_file"
    home.write_text("")
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env.update(PYTHONPATH=f"{tmp_path}{os.pathsep}{ROOT}", HOME=str(home))
    env.update(XDG_CACHE_HOME=str(home), PYTHONDONTWRITEBYTECODE="1")
    run = [sys.executable, "-c", "from ro_pkg import kernels as k; print(k.twice(2.5))"]
    for _ in range(2):  # and again: nothing was cached, it says so again
        proc = subprocess.run(run, env=env, capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0 and proc.stdout.strip() == "5.0", proc.stderr
        assert proc.stderr.count("no writable cache for the numba kernels") == 1, proc.stderr


@pytest.mark.skipif(not jit.ENABLED, reason="PEREGRINE_JIT=0: nothing is compiled")
def test_a_kernel_calling_one_of_another_file_recompiles_when_that_one_changes(tmp_path):
    # numba's cache checks only the caller's own source: without ``uses`` the caller would
    # keep the callee's old code inside it after an edit of the callee's file
    pkg = tmp_path / "pair_pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    callee = pkg / "callee.py"

    def write_callee(k: float, mtime: float) -> None:
        callee.write_text(
            "from onboard.jit import kernel\n"
            "@kernel('float64(float64)')\n"
            f"def scale(x):\n    return {k} * x\n"
        )
        os.utime(callee, (mtime, mtime))

    write_callee(2.0, 1_000_000_000.0)
    (pkg / "caller.py").write_text(
        "from onboard.jit import kernel\n"
        "from .callee import scale\n"
        "@kernel('float64(float64)', uses=(scale,))\n"
        "def caller(x):\n    return scale(x) + 1.0\n"
    )
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env.update(PYTHONPATH=f"{tmp_path}{os.pathsep}{ROOT}", PYTHONDONTWRITEBYTECODE="1")
    run = [sys.executable, "-c", "from pair_pkg import caller as c; print(c.caller(1.5))"]

    def result() -> str:
        proc = subprocess.run(run, env=env, capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0, proc.stderr
        return proc.stdout.strip()

    assert result() == "4.0"  # compiled and cached
    assert result() == "4.0"  # from the cache
    write_callee(3.0, 2_000_000_000.0)  # edited after the caller was cached
    assert result() == "5.5"


@pytest.mark.skipif(not jit.ENABLED, reason="PEREGRINE_JIT=0: nothing is compiled")
def test_kernels_compiled_under_other_options_are_compiled_again(tmp_path):
    # the compile options live in onboard/jit.py, which numba's cache does not check: a cache
    # older than it (made under other options, nogil for one) is dropped, not loaded
    (tmp_path / "opt_kernels.py").write_text(
        "from onboard.jit import kernel\n"
        "@kernel('float64(float64)')\n"
        "def twice(x):\n    return 2.0 * x\n"
    )
    newer_jit = tmp_path / "jit_edited.py"
    newer_jit.write_text("")
    env = _env_with_cache_in(tmp_path)
    script = (
        "import sys\nfrom onboard import jit\n"
        "if len(sys.argv) > 1: jit.__file__ = sys.argv[1]\n"
        "import opt_kernels as k\nprint(k.twice(2.0))\n"
    )

    def run(*args: str) -> str:
        proc = subprocess.run(
            [sys.executable, "-c", script, *args], env=env, capture_output=True, text=True,
            timeout=300,
        )  # fmt: skip
        assert proc.returncode == 0 and proc.stdout.strip() == "4.0", proc.stderr
        return proc.stderr

    assert "compiling" in run()
    assert "compiling" not in run()  # cached
    os.utime(newer_jit, (4_000_000_000.0, 4_000_000_000.0))  # the options edited since
    assert "compiling" in run(str(newer_jit))


def _busy(n):
    s = 0.0
    for i in range(n):
        s += (i % 7) * 0.5
    return s


@pytest.mark.skipif(not jit.ENABLED, reason="PEREGRINE_JIT=0: nothing is compiled")
def test_a_kernel_lets_the_gil_go_while_it_runs():
    # on the vehicle the control thread, waking for its tick, must not wait for another
    # thread's kernel (the camera thread's fusion) to end (onboard/jit.py _compile): other
    # Python threads run while a kernel does. Shown against the same function compiled to keep it
    import threading
    import time

    import numba

    released = jit._compile(_busy, "float64(int64)", cache=False)
    kept = numba.njit("float64(int64)", nogil=False)(_busy)
    n = 1_000_000
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < 0.02:  # n for a call of some 20 ms at least
        t0 = time.perf_counter()
        released(n)
        n *= 2
    counter = [0]
    stop = threading.Event()

    def other_thread() -> None:
        while not stop.is_set():
            counter[0] += 1
            time.sleep(0)  # lets the GIL go each round

    interval = sys.getswitchinterval()
    sys.setswitchinterval(1.0)  # the main thread keeps the GIL unless it releases it
    th = threading.Thread(target=other_thread, daemon=True)
    th.start()
    try:
        while counter[0] < 10:
            time.sleep(0.001)
        ran_during = {}
        for name, fn in (("kept", kept), ("released", released)):
            before = counter[0]
            fn(n)
            ran_during[name] = counter[0] - before
            time.sleep(0.005)
    finally:
        stop.set()
        sys.setswitchinterval(interval)
        th.join(5.0)
    assert ran_during["kept"] == 0  # the harness sees a kernel that keeps the GIL
    assert ran_during["released"] > 0
