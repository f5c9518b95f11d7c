"""Pure parts of the onboard runtime: the parameter table and the offboard state machine."""

import math

import pytest

from onboard.gains import GainError, Gains
from onboard.link import telemetry as tm
from onboard.link.params import PARAM_SPECS, ParamTable
from onboard.runtime.state_machine import (
    START_TIMEOUT_S,
    STREAM_BEFORE_OFFBOARD_S,
    Inputs,
    OffboardStateMachine,
    Output,
    State,
)


# ---------------------------------------------------------------------- parameters
def test_every_parameter_fits_mavlink_and_gains_are_all_there():
    names = [s.name for s in PARAM_SPECS]
    assert all(len(n) <= 16 for n in names)
    assert len(set(names)) == len(names)
    assert set(Gains().to_dict()) <= set(names)


def test_out_of_range_and_nonsense_values_are_refused_unchanged(tmp_path):
    table = ParamTable(tmp_path / "p.toml")
    for value in (99.0, -1.0, math.nan, math.inf):
        ok, why = table.set("v_max", value, flying=False)
        assert not ok and "v_max" in why
        assert table.get("v_max") == Gains().v_max
    assert table.version == 0
    assert not (tmp_path / "p.toml").exists()  # nothing changed, nothing written
    ok, why = table.set("no_such_param", 1.0, flying=False)
    assert not ok and "unknown" in why


def test_gains_change_in_flight_but_camera_and_law_do_not(tmp_path):
    table = ParamTable(tmp_path / "p.toml")
    assert table.set("k_a", 3.5, flying=True) == (True, "")
    ok, why = table.set("CAM_HFOV_DEG", 60.0, flying=True)
    assert not ok and "in flight" in why
    assert table.set("LAW", 1, flying=False) == (True, "")
    assert table.runtime.law == "pg"
    ok, _ = table.set("LAW", 1.5, flying=False)
    assert not ok and table.runtime.law == "pg"


def test_parameters_survive_a_restart_and_a_bad_file_is_refused(tmp_path):
    path = tmp_path / "params.toml"
    table = ParamTable(path)
    table.set("K_y", 4.25, flying=False)
    table.set("HOVER_THR", 0.45, flying=False)
    again = ParamTable(path)
    assert again.get("K_y") == 4.25 and again.get("HOVER_THR") == 0.45
    for text, needle in (
        ("K_y = 40\n", "K_y"),
        ("nonsense = 1\n", "unknown parameter"),
        ("K_y = \n", "not valid TOML"),
    ):
        path.write_text(text)
        with pytest.raises(GainError, match=needle):
            ParamTable(path)


def test_telemetry_layout_round_trips():
    vals = {name: float(i) + 0.5 for i, (name, _, _) in enumerate(tm.FIELDS)}
    data = tm.pack(vals)
    assert len(data) == tm.ARRAY_LEN
    assert tm.unpack(data) == vals
    partial = tm.unpack(tm.pack({"t_s": 1.0}))
    assert partial["t_s"] == 1.0 and partial["e_est_u_px"] is None
    with pytest.raises(KeyError):
        tm.pack({"not_a_field": 1.0})


# ---------------------------------------------------------------------- state machine
def _inputs(t, **kw):
    base = dict(
        now_s=t,
        fc_silence_s=0.1,
        armed=True,
        offboard=False,
        tracking=True,
        target_lost=False,
        target_size_frac=0.02,
        speed_m_s=0.0,
    )
    base.update(kw)
    return Inputs(**base)


def _to_intercept(sm):
    sm.step(_inputs(0.0))
    assert sm.state is State.READY
    assert sm.command_start() == (True, "start accepted")
    d = sm.step(_inputs(0.01))
    assert sm.state is State.STARTING and d.output is Output.LOOP and not d.request_offboard
    d = sm.step(_inputs(0.01 + STREAM_BEFORE_OFFBOARD_S))
    assert d.request_offboard and d.output is Output.LOOP  # setpoints stream first
    d = sm.step(_inputs(0.4, offboard=True))
    assert sm.state is State.INTERCEPT and d.output is Output.LOOP


def test_never_starts_by_itself_and_refuses_a_start_without_target():
    sm = OffboardStateMachine()
    assert sm.step(_inputs(0.0, fc_silence_s=None)).output is Output.NONE
    assert sm.state is State.LINK_DOWN
    assert sm.command_start()[0] is False
    assert sm.step(_inputs(0.1, tracking=False)).request_streams  # once, as the link comes up
    assert sm.state is State.WAITING_TARGET
    ok, why = sm.command_start()
    assert not ok and "no target" in why
    for k in range(100):  # ready for a long time: nothing is commanded or requested
        d = sm.step(_inputs(0.2 + 0.01 * k))
        assert d.output is Output.NONE and not (d.request_arm or d.request_offboard)
    assert sm.state is State.READY


def test_auto_start_is_only_an_explicit_option():
    sm = OffboardStateMachine(auto_start=True)
    sm.step(_inputs(0.0))
    sm.step(_inputs(0.01))
    assert sm.state is State.STARTING


def test_start_times_out_when_px4_refuses_offboard():
    sm = OffboardStateMachine()
    sm.step(_inputs(0.0))
    sm.command_start()
    sm.step(_inputs(0.01))
    d = sm.step(_inputs(0.02 + START_TIMEOUT_S))
    assert sm.state is State.READY and d.output is Output.NONE
    assert any("did not enter offboard" in t for _, t in d.events)


def test_target_lost_brakes_then_hands_over_to_px4_hold():
    sm = OffboardStateMachine(done_size_frac=0.2, hold_speed_m_s=0.3)
    _to_intercept(sm)
    d = sm.step(_inputs(1.0, offboard=True, tracking=False, target_lost=True, speed_m_s=6.0))
    assert sm.state is State.BRAKING and d.output is Output.BRAKE
    assert sm.reason == "target lost"
    d = sm.step(_inputs(1.5, offboard=True, tracking=False, target_lost=True, speed_m_s=2.0))
    assert d.output is Output.BRAKE and not d.request_hold
    d = sm.step(_inputs(2.5, offboard=True, tracking=False, target_lost=True, speed_m_s=0.2))
    assert d.request_hold
    d = sm.step(_inputs(2.6, offboard=False, tracking=False, target_lost=True))
    assert sm.state is State.FINISHED and d.output is Output.NONE


def test_a_target_lost_after_filling_the_view_is_a_finished_pass():
    sm = OffboardStateMachine(done_size_frac=0.2)
    _to_intercept(sm)
    sm.step(_inputs(1.0, offboard=True, target_size_frac=0.35))
    sm.step(_inputs(1.1, offboard=True, tracking=False, target_lost=True))
    assert sm.state is State.BRAKING and sm.reason == "pass done"


def test_a_stale_track_keeps_the_loop_flying_unless_the_pass_is_done():
    # coast, re-acquisition and search fly the loop's command; only its failsafe brakes
    sm = OffboardStateMachine(done_size_frac=0.2)
    _to_intercept(sm)
    d = sm.step(_inputs(1.0, offboard=True, tracking=False, target_stale=True))
    assert sm.state is State.INTERCEPT and d.output is Output.LOOP
    sm.step(_inputs(1.1, offboard=True, target_size_frac=0.35))
    d = sm.step(_inputs(1.2, offboard=True, tracking=False, target_stale=True))
    assert sm.state is State.BRAKING and sm.reason == "pass done" and d.output is Output.BRAKE


def test_abort_brakes_and_link_loss_stops_all_commands():
    sm = OffboardStateMachine()
    _to_intercept(sm)
    assert sm.command_abort()[0]
    d = sm.step(_inputs(1.0, offboard=True))
    assert sm.state is State.BRAKING and d.output is Output.BRAKE
    assert sm.reason == "aborted by the operator"
    d = sm.step(_inputs(1.2, offboard=True, fc_silence_s=1.5))
    assert sm.state is State.LINK_LOST and d.output is Output.NONE
    assert any(sev == "critical" for sev, _ in d.events)
    d = sm.step(_inputs(1.3, offboard=True, fc_silence_s=0.05))
    assert sm.state is State.READY and d.output is Output.NONE  # no automatic resumption


def test_px4_leaving_offboard_ends_the_sortie():
    sm = OffboardStateMachine()
    _to_intercept(sm)
    sm.step(_inputs(1.0, offboard=False))
    assert sm.state is State.INTERCEPT
    d = sm.step(_inputs(1.4, offboard=False))
    assert sm.state is State.FINISHED and d.output is Output.NONE


def test_a_new_sortie_can_start_after_one_finished():
    sm = OffboardStateMachine()
    _to_intercept(sm)
    sm.step(_inputs(1.0, offboard=False))
    sm.step(_inputs(1.4, offboard=False))
    assert sm.state is State.FINISHED
    sm.step(_inputs(1.5, tracking=False))
    assert sm.command_start()[0] is False  # nothing in view
    sm.step(_inputs(1.6))
    assert sm.state is State.FINISHED and sm.command_start()[0] is True
    sm.step(_inputs(1.7))
    assert sm.state is State.STARTING
