"""The TIMESYNC offset estimator against a synthetic flight-controller clock with an offset,
a skew and jittery link delays (seeded), symmetric and asymmetric."""

from __future__ import annotations

import numpy as np
import pytest

from onboard.link.timesync import TimesyncEstimator

SKEW = 80e-6  # the flight controller's clock runs 80 ppm fast


def fc_clock(t, t0: float = 5000.0, boot: float = 3.2):
    """The flight controller's boot clock at companion time ``t``."""
    return boot + (t - t0) * (1.0 + SKEW)


def _fly(est, rng, t_start: float, seconds: float, answer_wait_s: float = 0.0, clock=fc_clock):
    """Requests at 10 Hz; each way 0.3 ms + exponential jitter (mean 1 ms); the flight
    controller answers 0..``answer_wait_s`` after arrival (its loop: an asymmetry no estimator
    can see); 3 % of replies are held up by 60 ms more, 2 % lost. Returns the error of
    ``to_companion`` for a sample stamped by the flight controller, once converged."""
    errors = []
    for k in range(int(seconds * 10)):
        t1 = t_start + 0.1 * k + rng.uniform(0, 0.005)
        up = 3e-4 + rng.exponential(1e-3) + rng.uniform(0, answer_wait_s)
        down = 3e-4 + rng.exponential(1e-3) + (0.06 if rng.random() < 0.03 else 0.0)
        if rng.random() >= 0.02:
            est.add(t1, clock(t1 + up), t1 + up + down)
        if est.converged:
            t = t1 + 0.05
            errors.append(est.to_companion(clock(t)) - t)
    return np.array(errors)


def test_offset_and_skew_are_recovered_with_symmetric_jitter():
    est = TimesyncEstimator()
    err = np.abs(_fly(est, np.random.default_rng(17), 5000.0, 120.0)[30:])  # after 3 s
    # measured with this seed: median 0.035 ms, p99 0.15 ms, max 0.25 ms
    assert np.median(err) < 1e-4 and np.percentile(err, 99) < 2.5e-4 and err.max() < 4e-4
    assert est.skew == pytest.approx(-SKEW, abs=20e-6)  # the offset falls as the FC runs fast
    assert est.refused >= 20 and est.resets == 0  # the held-up replies (> 50 ms round trip)


def test_an_asymmetric_answer_delay_biases_by_at_most_half_of_it():
    est = TimesyncEstimator()
    err = _fly(est, np.random.default_rng(17), 5000.0, 120.0, answer_wait_s=1.7e-3)[30:]
    # the FC answers 0.85 ms late on average: half of that, minus what picking the quickest
    # round trips removes (measured: median 0.22 ms, p99 0.44 ms)
    assert np.median(np.abs(err)) < 0.85e-3 / 2 and np.percentile(np.abs(err), 99) < 0.7e-3


def test_a_flight_controller_reboot_restarts_the_estimate():
    rng = np.random.default_rng(3)
    est = TimesyncEstimator()
    _fly(est, rng, 5000.0, 20.0)
    assert est.converged
    err = _fly(est, rng, 5020.0, 30.0, clock=lambda t: fc_clock(t, t0=5020.0, boot=0.5))
    assert est.resets == 1
    assert np.abs(err[-100:]).max() < 4e-4  # settled again on the new clock


def test_nonsense_round_trips_are_refused_and_change_nothing():
    est = TimesyncEstimator()
    for t1, tc, t4 in ((1.0, 2.0, 0.9), (1.0, 2.0, 1.2), (float("nan"), 2.0, 1.0)):
        assert not est.add(t1, tc, t4)
    assert est.to_companion(5.0) is None and est.refused == 3 and not est.converged


def test_the_adapter_answers_px4s_requests_and_takes_answers_to_ours():
    from types import SimpleNamespace

    from onboard.link.px4 import mavlink
    from onboard.link.timesync import on_timesync, send_request

    sent = []
    mav = mavlink.MAVLink(None)
    link = SimpleNamespace(mav=mav, send=sent.append)
    est = TimesyncEstimator()
    on_timesync(link, est, SimpleNamespace(tc1=0, ts1=777), now_s=12.5)  # PX4 asks
    assert (sent[-1].tc1, sent[-1].ts1) == (12_500_000_000, 777)
    send_request(link, 20.0)
    assert (sent[-1].tc1, sent[-1].ts1) == (0, 20_000_000_000)
    for k in range(10):  # PX4 answers ours: its clock is ours - 7 s, 1 ms each way
        t1 = 20.0 + 0.1 * k
        on_timesync(link, est, SimpleNamespace(tc1=round((t1 - 6.999) * 1e9), ts1=round(t1 * 1e9)),
                    now_s=t1 + 0.002)  # fmt: skip
    assert est.accepted == 10 and est.to_companion(13.0) == pytest.approx(20.0, abs=1e-6)
    on_timesync(link, est, SimpleNamespace(tc1=5, ts1=round(3.0 * 1e9)), now_s=21.0)  # not ours
    assert est.accepted == 10 and est.refused == 0
