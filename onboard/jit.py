"""Compiled arithmetic: numba's nopython JIT for the loop's and the simulator's hot kernels.

A kernel is an ordinary Python function over floats and numpy arrays, decorated with
:func:`kernel` and an explicit numba signature. With the JIT on it is compiled when its module
is imported (from numba's on-disk cache after the first time, so a vehicle never compiles
mid-sortie) and runs the same IEEE operations in the same order as the Python source: no
fast-math, so no fused multiply-adds or reassociation. With the JIT off the very same
functions run as plain Python. There is one implementation of each kernel either way; its
readable statement in the paper's notation is its reference (``*_reference.py`` beside it,
tests/test_kernel_references.py).

The JIT pays only where thousands of sorties run: campaigns, tuning and benchmarks (about
200x real time compiled against 5x as Python) call :func:`use_jit` before they import a kernel
module. A single sortie, the web app and the vehicle run as Python by default: they start in
about a second instead of waiting for the compiler. ``PEREGRINE_JIT=1`` or ``PEREGRINE_JIT=0``
in the environment always wins. The mode is fixed when the first kernel is defined.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

F = TypeVar("F", bound=Callable[..., Any])

ENV = "PEREGRINE_JIT"  # "1": compile the kernels, "0": run them as Python
ENABLED = os.environ.get(ENV, "0") != "0"  # plain Python unless told

KERNELS: list[Callable[..., Any]] = []  # every kernel defined so far, compiled or not

_told: set[str] = set()  # what this process has said once already


def _tell_once(what: str, text: str) -> None:
    """Say ``text`` on stderr once per process (``what`` names it): why a start is slow."""
    if what not in _told:
        _told.add(what)
        print(f"peregrine: {text}", file=sys.stderr, flush=True)


def use_jit() -> bool:
    """Compile the kernels in this process and the processes it starts (campaign workers
    inherit the environment), unless ``PEREGRINE_JIT`` already says otherwise; returns the
    mode. Call it before any kernel module is imported: a mode change after a kernel was
    defined would leave some kernels compiled and others not, so it raises instead."""
    global ENABLED
    os.environ.setdefault(ENV, "1")
    wanted = os.environ[ENV] != "0"
    if wanted != ENABLED and KERNELS:
        raise RuntimeError(
            f"onboard.jit.use_jit() after {len(KERNELS)} kernels were defined as "
            f"{'compiled' if ENABLED else 'Python'}: call it before importing them"
        )
    ENABLED = wanted
    return ENABLED


def _tell_compiling(name: str) -> None:
    """The kernels are being compiled (the first compiled run after an install or an
    upgrade; cached on disk afterwards)."""
    _tell_once(
        "compiling",
        f"compiling the numba kernels ({name}, ...; campaigns, tuning and benchmarks run them "
        "compiled): once after an install or upgrade, one to a few minutes on 2 cores; cached "
        "on disk afterwards",
    )


def _tell_no_cache(name: str) -> None:
    """Nothing can be cached, so every start compiles."""
    _tell_once(
        "no cache",
        f"no writable cache for the numba kernels ({name}, ...): compiling them at every start "
        "(one to a few minutes on 2 cores); set NUMBA_CACHE_DIR to a writable directory",
    )


def _source_file(fn: Callable[..., Any]) -> str:
    return getattr(fn, "py_func", fn).__code__.co_filename


def _forget_if_stale(fn: Callable[..., Any], uses: Sequence[Callable[..., Any]]) -> None:
    """Drop ``fn``'s cached machine code when a kernel it calls from another file, or this
    file (the compile options: see :func:`_compile`), changed after it was cached: numba checks
    only the caller's own source (its documented limit), so an edited callee would otherwise
    keep flying in its old form inside the caller, and code compiled under other options would
    be loaded as it was."""
    from numba.core.caching import FunctionCache

    try:
        index = FunctionCache(fn)._cache_file._index_path
        cached = os.stat(index).st_mtime
        newest = max(os.stat(f).st_mtime for f in {__file__, *map(_source_file, uses)})
    except (OSError, RuntimeError, AttributeError):  # nothing cached, or no cache at all
        return
    if newest > cached:
        os.remove(index)


def _compile(
    fn: F, signature: str | None, cache: bool, uses: Sequence[Callable[..., Any]] = ()
) -> F:
    import numba

    if cache:
        _forget_if_stale(fn, uses)
    # nogil: a kernel call lets the GIL go, so a thread that wakes (the control thread) does
    # not wait for another thread's kernel (the camera thread's fusion) to finish
    options = {"cache": cache, "nogil": True}
    if signature is None:
        return numba.njit(**options)(fn)
    compiled = numba.njit(signature, **options)(fn)
    stats = getattr(compiled, "stats", None)  # a cache miss: it was compiled
    if cache and stats is not None and sum(stats.cache_misses.values()):
        _tell_compiling(fn.__qualname__)
    return compiled


def kernel(
    signature: str | None = None, uses: Sequence[Callable[..., Any]] = ()
) -> Callable[[F], F]:
    """Compile the decorated function with numba (``nopython``, cached, releases the GIL)
    for ``signature`` (eagerly, at import) or lazily on first call without one; with the JIT
    off (the default: see :func:`use_jit`) return it unchanged. ``uses``: functions of other
    files it calls or whose module constants it reads (its cache is dropped when one of those
    files changes; callees in its own file need not be named)."""

    def wrap(fn: F) -> F:
        if not ENABLED:
            KERNELS.append(fn)
            return fn
        try:
            compiled = _compile(fn, signature, cache=True, uses=uses)
        except RuntimeError as exc:
            if "cannot cache" not in str(exc):
                raise
            # no writable cache anywhere (the package's __pycache__, numba's per-user cache):
            # compile at every start rather than not start at all
            _tell_no_cache(fn.__qualname__)
            compiled = _compile(fn, signature, cache=False)
        KERNELS.append(compiled)
        return compiled

    return wrap
