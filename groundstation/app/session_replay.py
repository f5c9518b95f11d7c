"""Replay of a recorded sortie in the simulator session: open one (it replaces the sortie on
screen), compare the one on screen with another, and play, pause, seek or jump to the
closest approach. Commands run on the session's thread between ticks (``submit``). A mixin of
:class:`~.session.SimSession`."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from .errors import SessionError
from .replay import ReplayPlayer


class SessionReplay:
    """The replay commands of a :class:`~.session.SimSession`."""

    def open_replay(self, path: Path, name: str | None = None) -> None:
        player = ReplayPlayer(path, name)  # read (and validated) here, not on the sim thread

        def go():
            self._close_current("the operator opened a recorded sortie")
            self.sim = None
            self.replay, self.compare = player, None
            self.replay_t, self.replay_playing = 0.0, False
            self.state = "replay"
            self._new_epoch()
            self.speed = 1.0  # a recorded sortie opens at 1x, whatever the last sortie flew at
            self.config = dataclasses.replace(self.config, speed="1")
            self._trail_vehicle, self._trail_target = [], []
            if self.scene is not None:
                vehicle, target = player.trails(player.duration_s)
                self.scene.reset(
                    player.camera, player.diameter_m, player.scene_state(0.0), [*vehicle, *target]
                )
            self._force_frame = True
            self._publish(force=True)

        self.submit(go)

    def compare_with(self, path: Path, name: str | None = None) -> None:
        other = ReplayPlayer(path, name)

        def go():
            # idle: shown alone (B) until a sortie is started, which it is then overlaid on
            self.compare = other
            if self.scene is not None:
                self.scene.overlay(*other.trails(other.duration_s))
            self._publish(force=True)

        self.submit(go)

    def replay_command(self, action: str, t_s: float | None = None) -> None:
        def go():
            if self.replay is None:
                raise SessionError("no recorded sortie is open")
            if action == "play":
                if self.replay_t >= self.replay.duration_s - 1e-6:
                    self.replay_t = 0.0
                self.replay_playing = True
            elif action == "pause":
                self.replay_playing = False
            elif action == "seek":
                self.replay_t = min(max(float(t_s), 0.0), self.replay.duration_s)
                self._force_frame = True
            elif action == "closest":
                self.replay_t = self.replay.closest_time_s
                self.replay_playing = False
                self._force_frame = True
            else:
                raise SessionError(f"unknown replay action {action!r}")
            self._publish(force=True)

        self.submit(go)
