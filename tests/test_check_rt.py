"""``onboard check-rt``: the parsers on sample /proc and /sys contents, the histogram, and a
short run of the command itself."""

import pytest

from onboard.cli import main
from onboard.runtime.check_rt import (
    cmdline_value,
    cpu_list,
    histogram_lines,
    preemption_model,
    rlimit_text,
    wake_latencies_ms,
)

JETSON_CMDLINE = (
    "root=/dev/mmcblk0p1 rw rootwait console=ttyTCU0,115200n8 isolcpus=nohz,domain,managed_irq,5"
    " nohz_full=5 rcu_nocbs=5 quiet"
)


def test_cpu_lists_as_the_kernel_writes_them():
    assert cpu_list("0-2,5\n") == {0, 1, 2, 5}
    assert cpu_list("3") == {3}
    assert cpu_list("\n") == set()  # /sys/devices/system/cpu/isolated with nothing isolated
    for bad in ("a", "3-1", "-2", "1-x"):
        with pytest.raises(ValueError):
            cpu_list(bad)


def test_kernel_arguments_from_the_command_line():
    assert cmdline_value(JETSON_CMDLINE, "nohz_full") == "5"
    assert cmdline_value(JETSON_CMDLINE, "isolcpus") == "nohz,domain,managed_irq,5"
    assert cmdline_value(JETSON_CMDLINE, "quiet") == ""  # a bare flag
    assert cmdline_value(JETSON_CMDLINE, "irqaffinity") is None


@pytest.mark.parametrize(
    ("uname_v", "flag", "config", "dynamic", "expected"),
    [
        ("#1 SMP PREEMPT_RT Fri Sep 1 12:00:00 UTC 2023", None, None, None, "PREEMPT_RT"),
        ("#1 SMP PREEMPT RT Thu Aug 8 2024", None, None, None, "PREEMPT_RT"),  # L4T RT, 5.10
        ("#1 SMP PREEMPT_DYNAMIC Mon Jan 1 2024", "1\n", None, None, "PREEMPT_RT"),
        ("#1 SMP Mon", None, "CONFIG_PREEMPT_RT=y\n", None, "PREEMPT_RT"),
        ("#1 SMP PREEMPT_DYNAMIC @0", None, None, "none voluntary (full) lazy\n",
         "PREEMPT_DYNAMIC (full): not real-time"),
        ("#1 SMP PREEMPT_DYNAMIC @0", None, None, None, "PREEMPT_DYNAMIC (mode unknown)"),
        ("#1 SMP PREEMPT Tue", None, None, None, "PREEMPT (low-latency desktop)"),
        ("#1 SMP Tue", None, "# CONFIG_PREEMPT_RT is not set\nCONFIG_PREEMPT_VOLUNTARY=y\n",
         None, "voluntary preemption"),
        ("#1 SMP Tue", None, None, None, "no forced preemption"),
    ],
)  # fmt: skip
def test_the_preemption_model(uname_v, flag, config, dynamic, expected):
    assert preemption_model(uname_v, flag, config, dynamic).startswith(expected)


def test_rlimits_are_spelled_out():
    import resource

    inf = resource.RLIM_INFINITY
    assert rlimit_text(0, 0) == "0"
    assert rlimit_text(95, 99) == "95 (hard 99)"
    assert rlimit_text(inf, inf, " B") == "unlimited"
    assert rlimit_text(8388608, inf, " B") == "8388608 B (hard unlimited)"


def test_the_histogram_counts_each_latency_once():
    lines = histogram_lines([0.01, 0.02, 0.07, 0.3, 0.3, 0.3, 3.0, 12.0])
    counts = {line.split()[0]: int(line.split()[2]) for line in lines}
    assert counts["0-0.05"] == 2 and counts["0.05-0.1"] == 1 and counts["0.2-0.5"] == 3
    assert counts["2-5"] == 1 and counts["10+"] == 1
    assert sum(counts.values()) == 8
    assert lines[3].rstrip().endswith("#" * 40)  # the fullest bin has the whole bar


def test_wake_latencies_on_a_fake_clock():
    t = [0.0]

    def sleep_until(deadline):
        t[0] = deadline + 0.0001  # each wake-up 0.1 ms late

    lat = wake_latencies_ms(0.05, 0.005, sleep_until, lambda: t[0])
    assert len(lat) == 10 and lat == pytest.approx([0.1] * 10)


def test_check_rt_prints_what_this_computer_offers(capsys):
    assert main(["check-rt", "--seconds", "0.2"]) == 0
    out = capsys.readouterr().out
    needles = ("preemption model:", "isolated (isolcpus):", "nohz_full:", "RLIMIT_RTPRIO",
               "RLIMIT_MEMLOCK", "SCHED_FIFO", "mlockall:", "p50 ", " p99 ", "max ")  # fmt: skip
    for needle in needles:
        assert needle in out, out
    assert "wake-ups)" in out and "0-0.05 ms" in out


def test_check_rt_refuses_a_bad_duration(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["check-rt", "--seconds", "0"])
    assert exc.value.code == 2
