"""A simulated sortie run for the operator: paced against the wall clock (1x, 2x, 5x or as
fast as possible) in a thread of its own, steered by commands (start, pause, resume, step,
reset, speed, gains) and observed through telemetry snapshots published at a fixed rate.

Commands are queued and carried out by the simulation thread between control ticks, so a gain
edit takes effect at the next control tick of the running sortie.

Which gains a sortie flies is the rule in :mod:`.operator_gains` (docs/operator-gains.md).
"""

from __future__ import annotations

import dataclasses
import math
import queue
import threading
import time
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from onboard.gains import Gains

from ..scenario import load_scenario
from .errors import SessionError
from .numbers import fmt_num
from .operator_gains import FlownGains, OperatorGains
from .session_config import SPEEDS, SortieConfig, with_wind

if TYPE_CHECKING:
    from ..recording.writer import SortieRecorder
    from ..sim.simulation import Simulation
from .session_replay import SessionReplay
from .session_view import PUBLISH_HZ, SessionView

TRAIL_EVERY_S = 0.1
BEHIND_PUBLISH_HZ = 10.0  # snapshots per second while the simulator is starved (below)
# how far (wall seconds) the simulator may trail the clock and still publish every point of its
# grid: one slow step (a rendered frame, the garbage collector, a browser taking the CPU for a
# few ms) is caught up at the next iteration and must not cost the viewers a gap; further
# behind, a starved simulator (below) publishes a tenth of a second apart
BEHIND_TOLERANCE_S = 0.1
# starved: behind by more than BEHIND_TOLERANCE_S and it ran under this share of the control
# ticks due in the last second (a stall it is catching up from is not starving)
BEHIND_MIN_SHARE = 0.9
STEP_SLICE_S = 0.05  # most wall time one paced stepping call runs before commands are served
MAX_EVENTS = 200


__all__ = ["SPEEDS", "SessionError", "SimSession", "SortieConfig", "with_wind"]


class SimSession:
    """The operator's simulator: commands and the paced thread here; what the page sees is
    its ``view`` (:class:`~.session_view.SessionView`), the recorded sorties on screen its
    ``replays`` (:class:`~.session_replay.SessionReplay`)."""

    simulated = True  # the routers' Session protocol (protocol.py)
    foxglove = None  # a FoxgloveLive publishing each sortie's channels (serve --foxglove)

    def __init__(
        self,
        on_snapshot: Callable[[dict[str, Any]], None] | None = None,
        scene: Any | None = None,
        publish_hz: float = PUBLISH_HZ,
        log_dir: Path | None = None,
    ) -> None:
        self.log_dir = log_dir  # every sortie is recorded there (None: not recorded)
        self.on_snapshot = on_snapshot
        self.scene = scene
        self.publish_period_s = 1.0 / publish_hz
        self._commands: queue.Queue = queue.Queue()
        self.lock = threading.RLock()  # the plots' series, read by the web server's thread
        self._stop = threading.Event()
        self.config = SortieConfig(load_scenario("cv-top-to-bottom"))
        self.operator = OperatorGains()  # the operator's gain set and applied edits
        self.gains = self.operator.gain_set  # in force on the sortie on screen
        self.gains_base = self.gains  # the set the sortie on screen started from
        self.gains_source = "defaults"
        self.gains_note: str | None = None
        self.epoch = 0  # counts sorties shown (start, replay, reset): a page reloads its data
        self.events: list[list] = []  # [t_s, kind, text] of the sortie on screen
        self._last_mode: str | None = None
        self._last_lost = False
        self.sim: Simulation | None = None
        self.recorder: SortieRecorder | None = None  # observes the sortie on screen
        self.state = "idle"  # idle | running | paused | finished
        self.speed = 1.0
        self._anchor_wall = 0.0
        self._anchor_sim = 0.0
        self._tick_walls: deque[float] = deque()
        self._trail_vehicle: list[list[float]] = []
        self._trail_target: list[list[float]] = []
        self._last_trail_t = -1.0
        self.gains_applied_time_s: float | None = None
        self._gains_pending: Gains | None = None
        self.run_wall_s = 0.0  # wall time spent running (for the real-time ratio)
        self.run_sim_s = 0.0
        self.published_behind = 0  # snapshots published at the slower rate (the sim starved)
        self._next_publish_sim = 0.0  # the simulated time of the next snapshot (paced)
        self._last_publish_wall = 0.0  # when the last snapshot of a paced sortie went out
        self.view = SessionView(self)
        self.replays = SessionReplay(self)
        self._thread = threading.Thread(target=self._run, name="sim-session", daemon=True)
        self._thread.start()

    # ------------------------------------------------------------------ commands
    def submit(self, fn: Callable[[], Any], timeout_s: float = 5.0) -> Any:
        """Run ``fn`` on the simulation thread between ticks and return its result."""
        done = threading.Event()
        box: dict[str, Any] = {}

        def call():
            try:
                box["value"] = fn()
            except Exception as exc:
                box["error"] = exc
            finally:
                done.set()

        self._commands.put(call)
        if not done.wait(timeout_s):
            raise TimeoutError("the simulation thread did not answer")
        if "error" in box:
            raise box["error"]
        return box.get("value")

    def start(
        self,
        config: SortieConfig,
        target_track=None,
        sortie_gains: Gains | None = None,
        sortie_source: str | None = None,
    ) -> None:
        """Fly ``config``. ``sortie_gains``: gains for this sortie only (a re-fly, a study
        trial; ``sortie_source`` names them), else the operator's (module docstring)."""
        if config.speed not in SPEEDS:
            raise SessionError(f"speed must be one of {', '.join(SPEEDS)}")

        # the simulator and the recorder are imported at the first sortie, not when the
        # server starts (they pull the loop, the renderer and the channels in)
        from ..recording.writer import SortieRecorder
        from ..sim.simulation import Simulation

        def go():
            keep_compare = self.replays.compare if self.state == "idle" else None
            flown = self.operator.for_start(config.scenario, sortie_gains, sortie_source)
            self.close_current("the operator started another sortie")
            self.recorder = None if self.log_dir is None else SortieRecorder(self.log_dir)
            self.sim = Simulation(
                config.scenario,
                config.law,
                config.seed,
                config.camera,
                flown.gains,
                keep_records=False,
                observers=tuple(
                    o
                    for o in (self.recorder, self.foxglove and self.foxglove.observer())
                    if o is not None
                ),
                target_track=target_track,
            )
            self.config = config
            self._show_gains(flown)
            self._gains_pending = None
            self.gains_applied_time_s = None
            self.speed = SPEEDS[config.speed]
            self._trail_vehicle, self._trail_target = [], []
            self._last_trail_t = -1.0
            self.new_epoch()
            self._tick_walls.clear()
            self.run_wall_s = self.run_sim_s = 0.0
            self._set_running()
            if self.scene is not None:
                self.scene.reset(
                    self.sim.camera_model,
                    config.scenario.target.diameter_m,
                    self.view.scene_state(),
                )
            if keep_compare is not None:  # compared from an idle page: overlaid on this one
                self.replays.compare = keep_compare
                if self.scene is not None:
                    self.scene.overlay(*keep_compare.trails(keep_compare.duration_s))

        self.submit(go)

    def _set_running(self) -> None:
        self.state = "running"
        self._anchor_wall = time.perf_counter()
        self._anchor_sim = self.sim.time_s if self.sim else 0.0
        self._next_publish_sim = self._anchor_sim  # the first tick publishes
        self._last_publish_wall = 0.0

    def pause(self) -> None:
        def go():
            if self.state != "running":
                raise SessionError(f"cannot pause: the sortie is {self.state}")
            self.state = "paused"

        self.submit(go)

    def resume(self) -> None:
        def go():
            if self.state != "paused":
                raise SessionError(f"cannot resume: the sortie is {self.state}")
            self._set_running()

        self.submit(go)

    def step(self) -> None:
        """Advance one control period (from paused)."""

        def go():
            if self.state != "paused" or self.sim is None:
                raise SessionError("single-step needs a paused sortie")
            self._advance_one()
            if self.sim.done:
                self.state = "finished"
            self.view.publish(force=True)

        self.submit(go)

    def reset(self) -> None:
        def go():
            self.close_current("operator reset")
            self.sim = None
            self.replays.clear()
            self.state = "idle"
            # nothing flies: the gains shown are those a plain Start flies (a scenario with a
            # [gains] table aside), not the last re-fly's or trial's
            self._show_gains(self.operator.in_force())
            self._trail_vehicle, self._trail_target = [], []
            self.new_epoch()
            if self.scene is not None:
                self.scene.clear()
            self.view.publish(force=True)

        self.submit(go)

    def set_speed(self, speed: str) -> None:
        if speed not in SPEEDS:
            raise SessionError(f"speed must be one of {', '.join(SPEEDS)}")

        def go():
            self.speed = SPEEDS[speed]
            self.config = dataclasses.replace(self.config, speed=speed)
            if self.state == "running":
                self._set_running()

        self.submit(go)

    def set_gains(self, gains: Gains, source: str | None = None) -> Gains:
        """Use ``gains`` (already validated) from the running sortie's next control tick.
        With ``source`` (a gain set's name) they become the operator's gain set, without
        edits; otherwise the values changed are the operator's edits (they persist)."""

        def go():
            old = self.gains
            if source is not None:
                self.operator.load(gains, source)
                self._show_gains(self.operator.in_force())
            else:
                self.operator.take_edits(old, gains, self.gains_base)
            self.gains = gains
            t = None if self.sim is None else round(self.sim.time_s, 3)
            for k, v in gains.to_dict().items():
                before = getattr(old, k)
                if v != before:
                    self._event(t, "gain", f"{k} {fmt_num(before)} → {fmt_num(v)}")
            if self.sim is not None and not self.sim.done:
                self.sim.loop.set_gains(gains)
                self._gains_pending = gains
            return gains

        return self.submit(go)

    def _show_gains(self, flown: FlownGains) -> None:
        """The gains of the sortie on screen, the set they start from, its name and note."""
        self.gains, self.gains_base = flown.gains, flown.base
        self.gains_source, self.gains_note = flown.source, flown.note

    def reset_edits(self) -> Gains:
        """Drop the operator's edits: the sortie on screen flies its gain set again, and so
        does the next plain Start."""

        self.submit(self.operator.drop_edits)
        return self.set_gains(self.gains_base)

    def default_gains(self) -> Gains:
        """What "reset gains" restores: the base set in force, without the operator's edits."""
        return self.gains_base

    def live_command(self, action: str) -> dict[str, Any]:
        raise SessionError("simulator mode: there is no live vehicle")

    def gains_pending(self) -> bool:
        """An edit is applied to the running sortie and not yet flown by a control tick."""
        return self._gains_pending is not None

    # ------------------------------------------------------------------ what the page sees
    def status(self) -> dict[str, Any]:
        return self.view.status()

    def snapshot(self) -> dict[str, Any]:
        return self.view.snapshot()

    def series(self) -> dict[str, Any]:
        return self.view.series()

    @property
    def recording(self) -> dict[str, Any] | None:
        return self.view.recording

    def request_frame(self) -> None:
        self.view.request_frame()

    # ------------------------------------------------------------------ recorded sorties
    def open_replay(self, path: Path, name: str | None = None) -> None:
        self.replays.open(path, name)

    def compare_with(self, path: Path, name: str | None = None) -> None:
        self.replays.compare_with(path, name)

    def replay_command(self, action: str, t_s: float | None = None) -> None:
        self.replays.command(action, t_s)

    def new_epoch(self) -> None:
        """Another sortie on screen (start, replay, reset): a page reloads its data."""
        self.epoch += 1
        self.gains_applied_time_s = None  # an edit applied to an earlier sortie
        self.events = []
        self.view.new_sortie()
        self._last_mode, self._last_lost = None, False

    def _event(self, t_s: float | None, kind: str, text: str) -> None:
        if len(self.events) < MAX_EVENTS:
            self.events.append([t_s, kind, text])

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)
        self.close_current("the ground station stopped")

    def close_current(self, reason: str) -> None:
        """End the recording of the sortie on screen (an unfinished one is kept, marked
        INCOMPLETE with the reason: nothing recorded is ever lost)."""
        if self.sim is not None:
            self.sim.close(reason)
        self.replays.clear()

    # ------------------------------------------------------------------ the thread
    def _advance_one(self) -> None:
        sim = self.sim
        sim.step_control_period()
        now = time.perf_counter()
        walls = self._tick_walls  # appended and pruned here only: the simulation thread
        walls.append(now)
        while walls[0] < now - 1.0:
            walls.popleft()
        if self._gains_pending is not None and sim.loop.gains is self._gains_pending:
            self.gains_applied_time_s = sim.loop.last_tick_time_s
            self._gains_pending = None
        tel = sim.last_telemetry
        if tel is not None:
            mode = tel.mode.value
            if mode != self._last_mode:
                if self._last_mode is not None:
                    self._event(round(sim.time_s, 3), "state", f"{self._last_mode} → {mode}")
                self._last_mode = mode
            if tel.dkf_lost != self._last_lost and sim.loop.ladder.acquired:
                text = "detection lost" if tel.dkf_lost else "detection regained"
                self._event(round(sim.time_s, 3), "detection", text)
                self._last_lost = tel.dkf_lost
        self.view.record_history()
        if sim.done:
            self._event(
                round(sim.closest_time_s, 3),
                "closest",
                f"closest approach: {sim.outcome.value}, miss {fmt_num(sim.miss_m)} m",
            )
        if sim.time_s - self._last_trail_t >= TRAIL_EVERY_S:
            self._last_trail_t = sim.time_s
            self._trail_vehicle.append([round(c, 3) for c in sim.vehicle.p])
            self._trail_target.append([round(c, 3) for c in sim.target.p])

    def loop_rate_hz(self) -> float:
        """Control ticks run per wall-clock second, over the last second."""
        if self.state != "running":
            return 0.0
        now = time.perf_counter()
        # read-only here: status() is also called from the web server's thread
        recent = sum(1 for t in tuple(self._tick_walls) if t >= now - 1.0)
        return recent / min(1.0, max(now - self._anchor_wall, 1e-3))

    def _publish_gap_s(self, clock_sim_s: float) -> float:
        """The least wall time between two snapshots of a paced sortie (``clock_sim_s``: where
        the clock says the sortie should be). Zero while the simulator keeps up, trails by at
        most BEHIND_TOLERANCE_S or catches up (it ran at least BEHIND_MIN_SHARE of the control
        ticks due in the last second): every point of the grid goes out, those it passes while
        catching up after a stall too, each a state the plots take. Starved (further behind
        and running slower than that): a tenth of a second (BEHIND_PUBLISH_HZ), keeping its CPU
        for the simulation."""
        sim = self.sim
        if clock_sim_s - sim.time_s <= BEHIND_TOLERANCE_S * self.speed:
            return 0.0
        due_hz = sim.scenario.sim.control_rate_hz * self.speed
        if self.loop_rate_hz() < BEHIND_MIN_SHARE * due_hz:
            return 1.0 / BEHIND_PUBLISH_HZ
        return 0.0

    def _step_paced(self, now: float) -> bool:
        """Step a paced sortie (1x, 2x, 5x) up to where the clock says, publishing a snapshot
        each time the simulated time crosses the next point of its grid (the publish period
        times the speed: 40 a wall second when the simulator keeps real time). The snapshots
        are driven by the simulator's own steps, so every one carries a new state and none is
        lost to a late wake-up or a long step, which the simulator catches up with its
        snapshots. Starved, :meth:`_publish_gap_s` spaces them out. Returns whether the sortie
        is behind."""
        sim = self.sim
        period_sim = self.publish_period_s * self.speed
        target = self._anchor_sim + (now - self._anchor_wall) * self.speed
        # a simulator slower than the clock must still hand the thread back to the operator's
        # commands (pause, reset, speed) and the stop flag: at most STEP_SLICE_S of stepping
        slice_end = now + STEP_SLICE_S
        while not sim.done and sim.time_s < target:
            if time.perf_counter() > slice_end:
                break
            self._advance_one()
            if sim.time_s < self._next_publish_sim - 1e-9 and not sim.done:
                continue
            self._next_publish_sim = (math.floor(sim.time_s / period_sim + 1e-9) + 1) * period_sim
            if sim.done:
                break  # the finished sortie is published by the caller
            wall = time.perf_counter()
            gap_s = self._publish_gap_s(self._anchor_sim + (wall - self._anchor_wall) * self.speed)
            if wall < self._last_publish_wall + gap_s:
                continue
            if gap_s > 0.0:
                self.published_behind += 1
            self._last_publish_wall = wall
            self.view.publish()
        return sim.time_s < target

    def _run(self) -> None:
        next_publish = 0.0
        last_wall = time.perf_counter()
        last_wall_replay = last_wall
        was_running = behind = False
        nap_s = 0.01
        while not self._stop.is_set():
            now = time.perf_counter()
            if was_running:  # charge the whole last iteration (stepping, publishing, sleeping)
                self.run_wall_s += now - last_wall
            last_wall = now
            try:
                while True:
                    self._commands.get_nowait()()
            except queue.Empty:
                pass
            now = time.perf_counter()
            paced = False
            if self.state == "running" and self.sim is not None:
                sim = self.sim
                t_before = sim.time_s
                if math.isinf(self.speed):
                    # as fast as possible: step until the next snapshot is due on the wall grid
                    behind = False
                    deadline = max(next_publish, now + 0.002)
                    while not sim.done and time.perf_counter() < deadline:
                        self._advance_one()
                else:
                    paced = True
                    behind = self._step_paced(now)
                self.run_sim_s += sim.time_s - t_before
                if sim.done:
                    self.state = "finished"
                    next_publish = 0.0
                    paced = False
            self.replays.advance(now - last_wall_replay)
            last_wall_replay = now
            was_running = self.state == "running"
            now2 = time.perf_counter()
            if not paced and now2 >= next_publish:
                # not paced by the simulator (idle, paused, finished, replay, max speed): on a
                # fixed wall-clock grid; one more than half a period late starts it again
                self.view.publish()
                period = self.publish_period_s
                next_publish = max(next_publish + period, now2 + 0.5 * period)
            if paced:
                # nap until the next control tick is due (behind the clock: no nap), at most
                # 10 ms so that commands are taken promptly
                ahead_s = (self.sim.time_s - self._anchor_sim) / self.speed - (
                    now2 - self._anchor_wall
                )
                nap_s = 0.0 if behind else min(max(ahead_s, 0.0), 0.01)
            else:
                nap_s = 0.002 if was_running else 0.01
            self._stop.wait(nap_s)
