"""What the web server's routers ask of a session: the simulator's
(:class:`~.session.SimSession`, which also replays recorded sorties) and the live vehicle's
(:class:`~.live.LiveSession`) both implement it. A command a session cannot carry out raises
:class:`~.errors.SessionError`, which the routers answer 409 with its sentence; the routers
never ask which kind of session they have."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Protocol

from onboard.gains import Gains

from .session_config import SortieConfig


class Session(Protocol):
    """A session as the routers (groundstation/app/routes_*.py) and the server use it."""

    simulated: bool  # sorties are flown in the simulator (studies' trials can fly)
    log_dir: Path | None  # where sorties are recorded (None: not recorded)
    gains: Gains  # in force on the sortie on screen (live: as the vehicle last reported)
    foxglove: Any  # a FoxgloveLive publishing each sortie's channels, or None

    @property
    def recording(self) -> dict[str, Any] | None:
        """The recording of the sortie on screen: file, error, closed (None: none)."""
        ...

    def status(self) -> dict[str, Any]:
        """What the page's header and controls show (the ``Status`` model)."""
        ...

    def series(self) -> dict[str, Any]:
        """The sortie on screen so far: ``t_s``, plot ``columns`` and timeline ``events``."""
        ...

    def request_frame(self) -> None:
        """Send the camera frame with the next snapshot (a page has just connected)."""
        ...

    # ------------------------------------------------------------------ the simulator
    def start(
        self,
        config: SortieConfig,
        target_track: Any = None,
        sortie_gains: Gains | None = None,
        sortie_source: str | None = None,
    ) -> None: ...

    def pause(self) -> None: ...

    def resume(self) -> None: ...

    def step(self) -> None: ...

    def reset(self) -> None: ...

    def set_speed(self, speed: str) -> None: ...

    # ------------------------------------------------------------------ gains
    def set_gains(self, gains: Gains, source: str | None = None) -> Gains:
        """Fly ``gains`` from the next control tick (live: PARAM_SET each one that differs);
        ``source``: the name of the gain set they are (else they are the operator's edits)."""
        ...

    def reset_edits(self) -> Gains:
        """Drop the operator's edits: the gains the sortie started from fly again."""
        ...

    # ------------------------------------------------------------------ recorded sorties
    def open_replay(self, path: Path, name: str | None = None) -> None: ...

    def compare_with(self, path: Path, name: str | None = None) -> None: ...

    def replay_command(self, action: str, t_s: float | None = None) -> None: ...

    # ------------------------------------------------------------------ the live vehicle
    def live_command(self, action: str) -> dict[str, Any]:
        """``start`` or ``abort`` sent to the onboard computer; its acknowledgement."""
        ...

    def close(self) -> None: ...
