"""What the operating system gives the control thread: SCHED_FIFO at a priority, all memory
locked (``mlockall``: no page fault mid-tick) and a CPU of its own. Each is tried; what the
process may not have is named in one line, with how to grant it (docs/realtime.md)."""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import os
from dataclasses import dataclass

from .check_rt import isolated_cpus_of

# SCHED_FIFO priority of the control thread: below the kernel's interrupt threads (50 under
# PREEMPT_RT), which bring PX4's state and the camera's frames in
DEFAULT_PRIORITY = 40
_MCL_CURRENT, _MCL_FUTURE = 1, 2  # <sys/mman.h>, Linux
GRANT = (
    "grant them with LimitRTPRIO=99 and LimitMEMLOCK=infinity in the service's systemd unit "
    "(or CAP_SYS_NICE and CAP_IPC_LOCK); see docs/realtime.md"
)


@dataclass
class RealtimeSetup:
    """What took effect (None: not asked for) and what was refused, with why."""

    priority: int | None = None  # SCHED_FIFO priority in force
    memory_locked: bool | None = None
    cpus: frozenset[int] | None = None  # the control thread's CPUs when it was placed
    refused: tuple[str, ...] = ()
    # how the thread ran before (policy, priority, CPUs), for undo()
    before: tuple[int, int, set[int] | None] | None = None

    def figures(self) -> dict:
        return {
            "realtime_priority": self.priority,
            "memory_locked": self.memory_locked,
            "control_cpus": None if self.cpus is None else sorted(self.cpus),
            "realtime_refused": list(self.refused),
        }

    def undo(self) -> None:
        """Put the calling thread back as it was and unlock the memory (the loop is over; a
        test or an embedding goes on in this process)."""
        if self.before is None:
            return
        policy, priority, cpus = self.before
        with contextlib.suppress(AttributeError, OSError):
            if self.priority is not None:
                os.sched_setscheduler(0, policy, os.sched_param(priority))
            if self.cpus is not None and cpus is not None:
                os.sched_setaffinity(0, cpus)
        if self.memory_locked:
            with contextlib.suppress(OSError, AttributeError):
                _libc().munlockall()
        self.before = None

    def warning(self) -> str | None:
        """One line naming what could not be had and how to grant it, or None."""
        if not self.refused:
            return None
        return "onboard: real-time: no " + "; no ".join(self.refused) + f": {GRANT}"


def _libc() -> ctypes.CDLL:
    return ctypes.CDLL(ctypes.util.find_library("c") or None, use_errno=True)


def lock_memory() -> str | None:
    """``mlockall(MCL_CURRENT | MCL_FUTURE)``; None on success, else why not."""
    try:
        libc = _libc()
        if libc.mlockall(_MCL_CURRENT | _MCL_FUTURE) == 0:
            return None
        return os.strerror(ctypes.get_errno())
    except (OSError, AttributeError) as exc:
        return str(exc)


def isolated_cpus(allowed: set[int]) -> set[int]:
    """The CPUs isolated from the scheduler (``isolcpus=``) that this process may use."""
    try:
        with open("/sys/devices/system/cpu/isolated") as f:
            return isolated_cpus_of(f.read()) & allowed
    except OSError:
        return set()


def make_realtime(priority: int | None, cpu: int | None = None, lock: bool = True) -> RealtimeSetup:
    """On the calling thread (the control thread, after the other threads started, so they
    keep their normal policy): SCHED_FIFO at ``priority`` (None: not asked), ``mlockall`` when
    ``lock``, and the thread bound to ``cpu`` or, when None, to the isolated CPUs if the
    system has any this process may use."""
    setup = RealtimeSetup()
    refused: list[str] = []
    with contextlib.suppress(AttributeError, OSError):
        cpus = os.sched_getaffinity(0) if hasattr(os, "sched_getaffinity") else None
        setup.before = (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority, cpus)
    if priority is not None:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
            setup.priority = priority
        except (AttributeError, OSError) as exc:
            refused.append(f"SCHED_FIFO {priority} ({getattr(exc, 'strerror', None) or exc})")
    if lock:
        why = lock_memory()
        setup.memory_locked = why is None
        if why is not None:
            refused.append(f"mlockall ({why})")
    if hasattr(os, "sched_getaffinity"):
        allowed = os.sched_getaffinity(0)
        want = {cpu} if cpu is not None else isolated_cpus(allowed)
        if want:
            try:
                os.sched_setaffinity(0, want)
                setup.cpus = frozenset(want)
            except OSError as exc:
                refused.append(f"CPU {sorted(want)} ({exc.strerror or exc})")
    setup.refused = tuple(refused)
    return setup
