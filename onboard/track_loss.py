"""The loop's track-loss ladder: its mode at each tick from the DKF track's state and the
phase timers (waiting, tracking, coast, re-acquire, search, lost), and the screen that
detections pass while the track is not live (the rules and the commands of each rung are in
onboard/control/reacquire.py; docs/core.md, "Track loss, re-acquisition and search").

Pure: the times, the velocity and the gains are handed in; no clock, no I/O.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from .camera_model import CameraModel
from .control.guidance import line_of_sight
from .control.reacquire import Candidate, DetectionScreen, horizontal_unit
from .datatypes import Detection, LoopMode
from .estimation.dkf import DelayedKalmanFilter, ImageEstimate
from .gains import Gains

ATTITUDE_HISTORY_S = 1.0  # camera attitudes kept to place a delayed detection's LOS

PASS_DONE, TARGET_LOST = "pass done", "target lost"


def intercept_over(
    max_size_frac: float, done_size_frac: float, target_stale: bool, target_lost: bool
) -> str | None:
    """Why an intercept is over, or None: ``PASS_DONE`` once the target has filled
    ``done_size_frac`` of the view's width and the track then went stale (the vehicle flew
    past it), ``TARGET_LOST`` when the loop gave the target up. Either way the vehicle brakes
    and holds."""
    if target_stale and max_size_frac >= done_size_frac:
        return PASS_DONE
    if target_lost:
        return PASS_DONE if max_size_frac >= done_size_frac else TARGET_LOST
    return None


class TrackLossLadder:
    """Call :meth:`on_tick` once a tick with the camera attitude, then :meth:`next_mode`;
    :meth:`screening` and :meth:`screened` say which detections reach the DKF."""

    def __init__(self, camera: CameraModel, dkf: DelayedKalmanFilter) -> None:
        self.camera = camera
        self.dkf = dkf
        self.screen = DetectionScreen()
        self.acquired = False  # a track has been live since the start
        self.confirmed = False  # a track with n_confirm detections has been live since the start
        self.first_tick_s: float | None = None
        self.live_s = -math.inf  # last tick with a live (not stale) track
        self.coast_over = False  # the prediction's uncertainty ended this coast
        self.search_start_s: float | None = None
        self.search_cue: np.ndarray | None = None  # the heading the search flies (or None)
        self.search_dir = 1.0  # the yaw scan's first direction
        self.launch_cue: np.ndarray | None = None
        self.last_target_enu_m: np.ndarray | None = None  # where the track last put it (m)
        self.attitudes: deque[tuple[float, np.ndarray]] = deque()  # (tick time, R_WC)

    def on_tick(self, t: float, R_WC: np.ndarray) -> None:
        """Keep the camera attitude of the tick at ``t`` (s); the first tick takes the launch
        cue, where the operator pointed the camera (horizontal heading)."""
        if self.first_tick_s is None:
            self.first_tick_s = t
            self.launch_cue = horizontal_unit(R_WC[:, 2])
        hist = self.attitudes
        hist.append((t, R_WC))
        while len(hist) > 2 and hist[1][0] <= t - ATTITUDE_HISTORY_S:
            hist.popleft()

    def last_los(self, position_enu_m: np.ndarray) -> np.ndarray | None:
        """The unit LOS from ``position_enu_m`` to where the last track put the target (its
        range from the DKF), or None without one (or from there)."""
        p = self.last_target_enu_m
        if p is None:
            return None
        d = p - position_enu_m
        n = math.sqrt(float(d @ d))
        return d / n if n > 1e-6 else None

    def screening(self, t: float) -> bool:
        """Do detections go through the screen before the DKF? Not while its track is live
        (its own gate protects it), nor while waiting for the first one after the start (the
        operator started with the target in view: the first detection starts the track)."""
        if not self.confirmed:
            return self.search_start_s is not None
        return self.dkf.lost(t)

    def R_WC_at(self, time_s: float, R_now: np.ndarray) -> np.ndarray:
        """The camera attitude at the last tick at or before ``time_s`` (the oldest held if
        none; the current one if the history is empty)."""
        best = None
        for t_k, R in self.attitudes:
            if t_k > time_s + 1e-9:
                break
            best = R
        if best is None:
            return self.attitudes[0][1] if self.attitudes else R_now
        return best

    def screened(self, dets: list[Detection], R_WC: np.ndarray, gains: Gains) -> list[Detection]:
        """The detections (capture order) the screen lets through to the DKF now."""
        est = self.dkf.estimate()
        f = self.camera.f_px
        pred, sigma = None, 0.0
        if est is not None:
            pred = line_of_sight(est.e_px[0] / f, est.e_px[1] / f, R_WC)
            std = self.dkf.image_std_px()
            sigma = 0.0 if std is None else max(std) / f
        sharp = gains.coast_std  # px: a vaguer prediction confirms nothing alone
        out: list[Detection] = []
        for det in dets:
            try:
                ex, ey = self.camera.error_px(*(float(c) for c in det.center_px))
                t_c = float(det.capture_time_s)
            except (TypeError, ValueError):
                continue
            if not (math.isfinite(ex) and math.isfinite(ey) and math.isfinite(t_c)):
                continue
            los = line_of_sight(ex / f, ey / f, self.R_WC_at(t_c, R_WC))
            cand = Candidate(t_c, los)
            out.extend(self.screen.offer(det, cand, pred, sigma, gains, sharp / f))
        return out

    def next_mode(
        self, t: float, est: ImageEstimate | None, velocity_enu_m_s: np.ndarray, gains: Gains
    ) -> LoopMode:
        """The mode at the tick at ``t`` (s) from the track's state and the phase timers;
        updates the timers. ``velocity_enu_m_s``: the vehicle's (m/s), whose heading a search
        begun while moving flies when there is no launch cue."""
        g = gains
        if est is not None and not est.lost:
            # the first track is the loop's only once n_confirm detections are in it: the loss
            # of a lone false blob seen at the start then returns to the launch behaviour
            # (wait, then search along the launch heading) instead of re-acquiring nothing
            self.acquired = True
            if self.dkf.track_fused >= g.n_confirm:
                self.confirmed = True
            self.live_s = t
            self.coast_over = False
            self.search_start_s = None
            self.search_cue = None
            self.screen.clear()  # a later loss starts its confirmations afresh
            return LoopMode.TRACKING
        if est is not None:
            self.search_dir = -1.0 if self.camera.upright(*est.e_px)[0] > 0.0 else 1.0
        if not self.confirmed and self.search_start_s is None:
            if t - self.first_tick_s < g.t_wait:
                return LoopMode.WAITING
        elif self.confirmed and self.search_start_s is None:
            stale_s = t - self.live_s
            if est is not None:
                if not self.coast_over and stale_s < g.t_coast:
                    std = self.dkf.image_std_px()
                    if std is not None and max(std) <= g.coast_std:
                        return LoopMode.COAST
                    self.coast_over = True
                if stale_s < g.t_coast + g.t_reacq:
                    return LoopMode.REACQUIRE
        if self.search_start_s is None:
            self.search_start_s = t
            v = velocity_enu_m_s
            moving = math.sqrt(float(v @ v)) >= g.v_min if not self.confirmed else False
            cue = self.launch_cue if self.launch_cue is not None else horizontal_unit(v)
            self.search_cue = cue if moving else None
        if t - self.search_start_s < g.t_search:
            return LoopMode.SEARCH
        return LoopMode.LOST
