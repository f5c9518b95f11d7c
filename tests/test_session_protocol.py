"""The simulator's and the live vehicle's sessions both implement the routers' ``Session``
protocol (groundstation/app/protocol.py): every member, with the protocol's parameters."""

import inspect

import pytest

from groundstation.app.live import LiveSession
from groundstation.app.protocol import Session
from groundstation.app.session import SimSession

MEMBERS = sorted({n for n in vars(Session) if not n.startswith("_")} | set(Session.__annotations__))


def test_the_protocol_names_what_the_routers_use():
    assert {"status", "start", "set_gains", "reset_edits", "live_command", "simulated"} <= set(
        MEMBERS
    )


@pytest.mark.parametrize("cls", [SimSession, LiveSession])
@pytest.mark.parametrize("name", MEMBERS)
def test_each_session_implements_every_member(cls, name):
    want = getattr(Session, name, None)
    if name in Session.__annotations__ and not callable(want):
        # an attribute: set on the class or in __init__ (its source, or a base's, assigns it)
        sources = [inspect.getsource(c) for c in cls.__mro__ if c is not object]
        assert hasattr(cls, name) or any(f"self.{name} =" in s for s in sources), name
        return
    got = getattr(cls, name, None)
    assert got is not None, f"{cls.__name__} has no {name}"
    if isinstance(want, property):
        assert isinstance(got, property), name
        return
    params = [p for p in inspect.signature(want).parameters if p != "self"]
    have = inspect.signature(got).parameters
    if any(p.kind is p.VAR_POSITIONAL for p in have.values()):
        return  # a command the session refuses whatever it is given (live: start, pause…)
    assert [p for p in have if p != "self"] == params, (cls.__name__, name)


def test_the_simulator_refuses_a_live_command_with_a_sentence():
    from groundstation.app.errors import SessionError

    with pytest.raises(SessionError, match="simulator mode: there is no live vehicle"):
        SimSession.live_command(None, "start")
