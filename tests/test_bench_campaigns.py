"""``groundstation bench --campaigns`` reads how much of the machine was idle during a run."""

import os
import sys
import time

import pytest

from groundstation.bench.campaigns import _TICK_S, _idle_cpu_s


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc/stat is Linux's")
def test_idle_cpu_seconds_grow_by_at_most_every_core_for_the_wall_time():
    t0, idle0 = time.monotonic(), _idle_cpu_s()
    time.sleep(0.3)
    idle1, wall = _idle_cpu_s(), time.monotonic() - t0
    cores = os.cpu_count() or 1
    assert idle0 is not None and idle1 is not None
    assert 0.0 <= idle1 - idle0 <= cores * wall + 2 * cores * _TICK_S
