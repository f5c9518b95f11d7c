"""The campaign workers' process pool: its start method, and starting its server early.

Workers fork from a server process that has imported the simulator (its compiled kernels
loaded) once: a worker is ready as soon as it is forked, instead of importing and loading
the kernels itself. The server is started by the batch commands before they import the
simulator themselves, so that its import runs beside theirs on another core rather than after
it; by the time the first pool is made it is ready."""

from __future__ import annotations

import multiprocessing
import os
from multiprocessing.context import BaseContext

# what the server imports before it forks any worker: the runner, and through it the
# simulator and every kernel module it uses (a module name: no import here)
PRELOAD = "groundstation.campaigns.runner"


def default_workers() -> int:
    """The processes a pool uses by default: the CPUs this process may run on."""
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return max(1, os.cpu_count() or 1)


def pool_context() -> BaseContext:
    """Workers fork from a clean server process that has already imported the simulator:
    no inherited OpenCV or BLAS thread state (unlike plain fork), and no per-worker import
    cost (unlike spawn). Platforms without forkserver use spawn."""
    if "forkserver" in multiprocessing.get_all_start_methods():
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload([PRELOAD])
        return ctx
    return multiprocessing.get_context("spawn")


def start_pool_server(workers: int | None) -> bool:
    """Start the workers' server now, in the background, when a pool of more than one worker
    will be used (``workers`` None: one per CPU); True if it was started. It imports the
    simulator beside this process's own import."""
    if (workers if workers is not None else default_workers()) <= 1:
        return False
    ctx = pool_context()
    if ctx.get_start_method() != "forkserver":
        return False
    from multiprocessing import forkserver

    forkserver.ensure_running()
    return True
