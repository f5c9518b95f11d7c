"""Replay of a recorded sortie in the simulator session: open one (it replaces the sortie on
screen), compare the one on screen with another, and play, pause, seek or jump to the
closest approach. A part of :class:`~.session.SimSession` (``session.replays``): it holds the
recorded sortie on screen, the one compared with it and the cursor; its commands run on the
session's thread between ticks (``submit``)."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import TYPE_CHECKING

from .errors import SessionError
from .replay import ReplayPlayer

if TYPE_CHECKING:
    from .session import SimSession

REPLAY_MAX_X = 50.0  # recorded seconds per wall second when the pace is "max"


class SessionReplay:
    """The recorded sortie on screen (``player``), the one compared with what is on screen
    (``compare``) and the replay cursor (``t_s``, ``playing``)."""

    def __init__(self, session: SimSession) -> None:
        self.session = session
        self.player: ReplayPlayer | None = None
        self.compare: ReplayPlayer | None = None
        self.t_s = 0.0
        self.playing = False

    def clear(self) -> None:
        self.player = self.compare = None

    def speed_x(self) -> float:
        """Recorded seconds played per wall second ("max" plays at REPLAY_MAX_X)."""
        speed = self.session.speed
        return REPLAY_MAX_X if math.isinf(speed) else speed

    def advance(self, wall_s: float) -> None:
        """The cursor of a recorded sortie playing moved on by ``wall_s`` of wall time."""
        if self.session.state != "replay" or self.player is None or not self.playing:
            return
        self.t_s = min(self.t_s + wall_s * self.speed_x(), self.player.duration_s)
        if self.t_s >= self.player.duration_s:
            self.playing = False

    def open(self, path: Path, name: str | None = None) -> None:
        player = ReplayPlayer(path, name)  # read (and validated) here, not on the sim thread
        s = self.session

        def go():
            s.close_current("the operator opened a recorded sortie")
            s.sim = None
            self.player, self.compare = player, None
            self.t_s, self.playing = 0.0, False
            s.state = "replay"
            s.new_epoch()
            s.speed = 1.0  # a recorded sortie opens at 1x, whatever the last sortie flew at
            s.config = dataclasses.replace(s.config, speed="1")
            s._trail_vehicle, s._trail_target = [], []
            if s.scene is not None:
                vehicle, target = player.trails(player.duration_s)
                s.scene.reset(
                    player.camera, player.diameter_m, player.scene_state(0.0), [*vehicle, *target]
                )
            s.view.request_frame()
            s.view.publish(force=True)

        s.submit(go)

    def compare_with(self, path: Path, name: str | None = None) -> None:
        other = ReplayPlayer(path, name)
        s = self.session

        def go():
            # idle: shown alone (B) until a sortie is started, which it is then overlaid on
            self.compare = other
            if s.scene is not None:
                s.scene.overlay(*other.trails(other.duration_s))
            s.view.publish(force=True)

        s.submit(go)

    def command(self, action: str, t_s: float | None = None) -> None:
        s = self.session

        def go():
            if self.player is None:
                raise SessionError("no recorded sortie is open")
            if action == "play":
                if self.t_s >= self.player.duration_s - 1e-6:
                    self.t_s = 0.0
                self.playing = True
            elif action == "pause":
                self.playing = False
            elif action == "seek":
                self.t_s = min(max(float(t_s), 0.0), self.player.duration_s)
                s.view.request_frame()
            elif action == "closest":
                self.t_s = self.player.closest_time_s
                self.playing = False
                s.view.request_frame()
            else:
                raise SessionError(f"unknown replay action {action!r}")
            s.view.publish(force=True)

        s.submit(go)
