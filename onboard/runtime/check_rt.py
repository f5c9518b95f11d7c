"""``onboard check-rt``: what this computer offers a real-time control loop. The kernel's
preemption model, the CPUs isolated from the scheduler (``isolcpus``, ``nohz_full``,
``rcu_nocbs``), the limits on real-time priority and locked memory, whether SCHED_FIFO and
``mlockall`` are permitted to this process, and the wake-up latency of a periodic sleep
(a histogram). docs/realtime.md says how to read it and what a Jetson needs.

The parsers take the text of the /proc and /sys files, so they are tested on samples."""

from __future__ import annotations

import ctypes
import ctypes.util
import math
import os
import platform
import re
import threading
import time
from collections.abc import Callable, Sequence

# wake-up latency bins (upper edges, ms) of the text histogram
LATENCY_BINS_MS = (0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0, math.inf)
BAR_WIDTH = 40


def cpu_list(text: str) -> set[int]:
    """The CPUs of a kernel CPU list ("0-2,5", "" for none). Raises ValueError on anything
    else."""
    out: set[int] = set()
    for part in text.strip().split(","):
        part = part.strip()
        if not part:
            continue
        lo, sep, hi = part.partition("-")
        first, last = int(lo), int(hi) if sep else int(lo)
        if first < 0 or last < first:
            raise ValueError(f"not a CPU range: {part!r}")
        out.update(range(first, last + 1))
    return out


def isolated_cpus_of(text: str) -> set[int]:
    """/sys/devices/system/cpu/isolated's CPUs (``isolcpus=``)."""
    return cpu_list(text)


def cmdline_value(cmdline: str, name: str) -> str | None:
    """The value of kernel argument ``name`` in /proc/cmdline (``""`` for a bare flag), or
    None when absent."""
    for arg in cmdline.split():
        key, sep, value = arg.partition("=")
        if key == name:
            return value if sep else ""
    return None


def preemption_model(
    uname_version: str, realtime_flag: str | None, config: str | None, dynamic: str | None
) -> str:
    """The kernel's preemption model from ``uname -v``, /sys/kernel/realtime (None when
    absent), the kernel's build configuration (/boot/config-*, /proc/config.gz; None when not
    found) and the dynamic model in force (/sys/kernel/debug/sched/preempt, the one in
    parentheses; None when not readable)."""
    if (realtime_flag or "").strip() == "1" or re.search(r"\bPREEMPT[_ ]RT\b", uname_version):
        return "PREEMPT_RT (fully preemptible, real-time)"
    if config is not None and _config_set(config, "CONFIG_PREEMPT_RT"):
        return "PREEMPT_RT (fully preemptible, real-time)"
    mode = None
    if dynamic:
        for word in dynamic.split():
            if word.startswith("(") and word.endswith(")"):
                mode = word[1:-1]
    words = uname_version.split()
    if "PREEMPT_DYNAMIC" in words:
        return f"PREEMPT_DYNAMIC ({mode or 'mode unknown'}): not real-time"
    if "PREEMPT" in words or (config is not None and _config_set(config, "CONFIG_PREEMPT")):
        return "PREEMPT (low-latency desktop): not real-time"
    if config is not None and _config_set(config, "CONFIG_PREEMPT_VOLUNTARY"):
        return "voluntary preemption: not real-time"
    return "no forced preemption (server): not real-time"


def _config_set(config: str, name: str) -> bool:
    return any(line.strip() == f"{name}=y" for line in config.splitlines())


def rlimit_text(soft: int, hard: int, unit: str = "") -> str:
    """An rlimit pair as ``getrlimit`` gives it, infinity spelled out."""

    def one(v: int) -> str:
        return "unlimited" if v == _RLIM_INFINITY else f"{v}{unit}"

    return one(soft) if soft == hard else f"{one(soft)} (hard {one(hard)})"


_RLIM_INFINITY = -1
try:
    import resource

    _RLIM_INFINITY = resource.RLIM_INFINITY
except ImportError:  # not POSIX
    resource = None  # type: ignore[assignment]


def percentile(xs: Sequence[float], q: float) -> float:
    s = sorted(xs)
    return s[min(len(s) - 1, int(q * len(s)))]


def histogram_lines(latencies_ms: Sequence[float]) -> list[str]:
    """A text histogram of wake-up latencies (ms) over :data:`LATENCY_BINS_MS`."""
    counts = [0] * len(LATENCY_BINS_MS)
    for x in latencies_ms:
        for i, edge in enumerate(LATENCY_BINS_MS):
            if x < edge:
                counts[i] += 1
                break
    top = max(counts) or 1
    lines, lo = [], 0.0
    for edge, n in zip(LATENCY_BINS_MS, counts, strict=True):
        label = f"{lo:g}+ ms" if math.isinf(edge) else f"{lo:g}-{edge:g} ms"
        bar = "#" * math.ceil(BAR_WIDTH * n / top) if n else ""
        lines.append(f"  {label:>12s} {n:7d} {bar}")
        lo = edge
    return lines


def wake_latencies_ms(
    seconds: float,
    period_s: float = 0.005,
    sleep_until: Callable[[float], None] | None = None,
    clock: Callable[[], float] = time.monotonic,
) -> list[float]:
    """Sleep to ``period_s``-spaced absolute deadlines for ``seconds``; how late each wake-up
    was (ms)."""
    if sleep_until is None:
        from .scheduler import default_sleep_until

        sleep_until = default_sleep_until()
    out = []
    t0 = clock()
    for k in range(1, max(round(seconds / period_s), 1) + 1):
        deadline = t0 + k * period_s
        sleep_until(deadline)
        out.append(1000.0 * (clock() - deadline))
    return out


def _read(path: str) -> str | None:
    try:
        with open(path) as f:
            return f.read()
    except OSError:
        return None


def _kernel_config() -> str | None:
    text = _read(f"/boot/config-{platform.release()}")
    if text is not None:
        return text
    try:
        import gzip

        with gzip.open("/proc/config.gz", "rt") as f:
            return f.read()
    except OSError:
        return None


def fifo_permitted(priority: int) -> str | None:
    """Try SCHED_FIFO at ``priority`` on a short-lived thread; None when permitted, else why
    not."""
    why: list[str] = []

    def attempt() -> None:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
        except (AttributeError, OSError) as exc:
            why.append(getattr(exc, "strerror", None) or str(exc))

    t = threading.Thread(target=attempt)
    t.start()
    t.join()
    return why[0] if why else None


def mlockall_permitted() -> str | None:
    """Try ``mlockall(MCL_CURRENT)`` and undo it; None when permitted, else why not."""
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or None, use_errno=True)
        if libc.mlockall(1) != 0:
            return os.strerror(ctypes.get_errno())
        libc.munlockall()
        return None
    except (OSError, AttributeError) as exc:
        return str(exc)


def report(seconds: float, priority: int | None, out: Callable[[str], None] = print) -> int:
    """Print what this computer offers (``onboard check-rt``)."""
    uname_v = platform.version()
    model = preemption_model(
        uname_v,
        _read("/sys/kernel/realtime"),
        _kernel_config(),
        _read("/sys/kernel/debug/sched/preempt"),
    )
    out(f"kernel: {platform.release()} {uname_v}")
    out(f"  preemption model: {model}")
    cmdline = _read("/proc/cmdline") or ""
    iso = _read("/sys/devices/system/cpu/isolated")
    iso_cpus = sorted(isolated_cpus_of(iso)) if iso is not None else None
    out(f"  CPUs: {os.cpu_count()}; isolated (isolcpus): "
        + ("unknown" if iso_cpus is None else ", ".join(map(str, iso_cpus)) or "none"))  # fmt: skip
    for arg in ("isolcpus", "nohz_full", "rcu_nocbs", "irqaffinity"):
        value = cmdline_value(cmdline, arg)
        out(f"  {arg}: {'not set' if value is None else value or '(flag)'}")
    if resource is not None:
        rtprio = rlimit_text(*resource.getrlimit(resource.RLIMIT_RTPRIO))
        memlock = rlimit_text(*resource.getrlimit(resource.RLIMIT_MEMLOCK), " B")
        out(f"limits: RLIMIT_RTPRIO {rtprio}, RLIMIT_MEMLOCK {memlock}")
    fifo = fifo_permitted(priority) if priority is not None else "not asked"
    lock = mlockall_permitted()
    if priority is not None:
        out(f"  SCHED_FIFO {priority}: " + ("permitted" if fifo is None else f"refused ({fifo})"))
    out("  mlockall: " + ("permitted" if lock is None else f"refused ({lock})"))
    policy = f"SCHED_FIFO {priority}" if fifo is None else "normal scheduling"
    out(f"wake-up latency of a 5 ms periodic sleep for {seconds:g} s ({policy}):")
    lat = _measure(seconds, priority if fifo is None else None)
    if not lat:
        out("  no wake-ups measured")
        return 0
    p50, p90, p99 = (percentile(lat, q) for q in (0.5, 0.9, 0.99))
    out(f"  p50 {p50:.3f} ms, p90 {p90:.3f} ms, p99 {p99:.3f} ms, max {max(lat):.3f} ms "
        f"({len(lat)} wake-ups)")  # fmt: skip
    for line in histogram_lines(lat):
        out(line)
    return 0


def _measure(seconds: float, priority: int | None) -> list[float]:
    """:func:`wake_latencies_ms` on a thread of its own (under SCHED_FIFO ``priority``)."""
    got: list[float] = []

    def run() -> None:
        if priority is not None:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
        got.extend(wake_latencies_ms(seconds))

    t = threading.Thread(target=run, name="check-rt")
    t.start()
    t.join()
    return got
