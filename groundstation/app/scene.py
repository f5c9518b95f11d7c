"""The 3D view (viser): ground grid, the interceptor with body axes and camera frustum, the
target at its true size, both trails, the line of sight, and the closest-approach point when
the sortie ends. Handles are created once and mutated inside ``server.atomic()``."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import viser

from onboard.camera_model import CameraModel
from onboard.geometry import quat_to_rotmat, rotmat_to_quat


@dataclass(frozen=True)
class SceneState:
    """What the 3D view shows at one instant, from a running sortie or a recorded one."""

    time_s: float
    vehicle_p: tuple[float, float, float]
    vehicle_q: tuple[float, float, float, float]  # (w, x, y, z)
    target_p: tuple[float, float, float]
    closest_point: tuple[float, float, float] | None = None  # once the sortie has ended
    outcome_label: str = ""


VEHICLE_RGB = (230, 60, 40)
TARGET_RGB = (220, 20, 20)
TRAIL_VEHICLE_RGB = (30, 110, 230)
TRAIL_TARGET_RGB = (40, 40, 40)
LOS_RGB = (250, 170, 0)
# a compared sortie ("B"), in the colour the plots give it
COMPARE_VEHICLE_RGB = (0, 168, 168)
COMPARE_TARGET_RGB = (0, 110, 110)
VIEW_PRESETS = ("fit engagement", "follow vehicle", "chase", "top")
FIT_FILL = 0.8  # "fit engagement": the farthest point this far from the view's centre (of 1)
FIT_DIRECTION = (-0.6, -0.2, 0.3)  # the fit's eye from the engagement: west-south-west, above
START_EYE_M = (-11.0, 1.0, 12.0)  # the camera a new viewer starts with, before it is framed


def fit_camera(
    points: np.ndarray,
    vfov_rad: float,
    aspect: float,
    direction: tuple[float, float, float] = FIT_DIRECTION,
    fill: float = FIT_FILL,
) -> tuple[np.ndarray, np.ndarray]:
    """The camera (eye, look-at) from ``direction`` (+z up) that frames ``points`` (N x 3, m):
    the look-at is the centre of their extent across the view, and the eye as close as the
    farthest point allows at ``fill`` of the half-view (perspective, ``vfov_rad`` vertical,
    ``aspect`` width over height)."""
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    back = np.asarray(direction, dtype=float)
    back /= np.linalg.norm(back)
    fwd = -back
    right = np.cross(fwd, (0.0, 0.0, 1.0))
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    c0 = (p.min(axis=0) + p.max(axis=0)) / 2.0
    a, b, z = (p - c0) @ right, (p - c0) @ up, (p - c0) @ fwd
    centre = c0 + right * (a.min() + a.max()) / 2.0 + up * (b.min() + b.max()) / 2.0
    a, b = a - (a.min() + a.max()) / 2.0, b - (b.min() + b.max()) / 2.0
    tan_v = math.tan(vfov_rad / 2.0)
    tan_h = tan_v * aspect
    # point i at depth d + z_i shows at |a_i| / ((d + z_i) tan_h) of the half-width
    d = float(np.max(np.maximum(np.abs(a) / (fill * tan_h), np.abs(b) / (fill * tan_v)) - z))
    d = max(d, float(np.max(-z)) + 1.0, 3.0)  # in front of every point, and not inside
    return centre + back * d, centre


class SceneView:
    def __init__(self, server: viser.ViserServer) -> None:
        self.server = server
        server.scene.set_up_direction("+z")
        # Shadows and image-based lighting cost every viewer a lot of GPU time per render,
        # which software GL (a laptop without GPU, a headless browser) cannot afford.
        server.scene.configure_default_lights(enabled=True, cast_shadow=False)
        server.scene.configure_environment_map(hdri=None)
        server.scene.add_grid(
            "/ground",
            width=60.0,
            height=60.0,
            cell_size=5.0,
            section_size=10.0,
            position=(0.0, 15.0, 0.0),
        )
        # a scale for the grid: distances along its west and south edges, and the cell size
        for k, y in enumerate(range(-10, 50, 10)):
            server.scene.add_label(f"/ground/scale/n{k}", f"N {y} m", position=(-30.0, y, 0.0))
        for k, x in enumerate(range(-20, 30, 10)):
            server.scene.add_label(f"/ground/scale/e{k}", f"E {x} m", position=(x, -15.0, 0.0))
        server.scene.add_label("/ground/scale/cell", "grid: 5 m cells", position=(30.0, -15.0, 0))
        # the engagement happens 0-35 m north of the origin, 0-20 m up
        server.initial_camera.position = START_EYE_M
        server.initial_camera.look_at = (0.0, 14.0, 5.0)
        # the control panel small: at a laptop's 1280 x 800 the view is about 550 px wide and
        # viser shows it as a sheet at the bottom, which web/scene3d.js moves to the top-right
        server.gui.configure_theme(control_width="small", show_share_button=False)
        self._views: dict[int, Any] = {}  # client id -> its view preset dropdown
        self._bounds: tuple[np.ndarray, np.ndarray] | None = None  # of the sortie on screen
        self._extent: np.ndarray | None = None  # the trajectories' points, to frame them
        server.on_client_connect(self._add_view_control)
        server.on_client_disconnect(lambda c: self._views.pop(c.client_id, None))
        self._vehicle = None
        self._target = None
        self._frustum = None
        self._diameter = None
        self._trail_time_s = -1.0
        self._shown: tuple | None = None  # the last update's state and trail lengths
        self._closest_shown = self._fitted_done = False
        self._extent_fixed = False  # a recorded sortie's whole trajectories are the extent
        self._handles: list = []  # every node a sortie added, children before parents
        self._labels: list = []

    def _add_view_control(self, client: Any) -> None:
        """Each viewer picks its own view: one operator following the vehicle does not move
        another's camera."""
        dd = client.gui.add_dropdown("View", VIEW_PRESETS, initial_value="fit engagement")
        self._views[client.client_id] = dd
        fitted_aspect: list[float] = []

        @client.camera.on_update
        def _(camera) -> None:
            # The first report gives the view's size: frame it then. A later change of size
            # (the page laid out again, a resized window) frames it again; orbiting does not.
            # A report still at the start's camera frames it again too: a busy browser can
            # report its start camera after the framing was sent, over the framing.
            aspect = float(camera.aspect)
            resized = not fitted_aspect or abs(aspect - fitted_aspect[0]) > 0.03 * fitted_aspect[0]
            if not resized and not np.allclose(camera.position, START_EYE_M):
                return
            fitted_aspect[:] = [aspect]
            self._apply_static_view(client, dd.value)

        @dd.on_update
        def _(_event) -> None:
            self._shown = None  # a moving preset is placed by the next update, paused or not
            self._apply_static_view(client, dd.value)

    def _apply_static_view(self, client: Any, preset: str) -> None:
        if preset not in ("fit engagement", "top"):
            return
        pts = self._extent
        if pts is None or len(pts) < 2:
            pts = np.array([[-5.0, 0.0, 0.0], [5.0, 35.0, 15.0]])
        cam = client.camera
        try:
            vfov, aspect = float(cam.fov), float(cam.aspect)
        except (AssertionError, ZeroDivisionError):  # no camera report yet
            vfov, aspect = math.radians(75.0), 1.3
        direction = FIT_DIRECTION if preset == "fit engagement" else (0.0, -0.01, 1.0)
        eye, look = fit_camera(pts, vfov, aspect, direction)
        with client.atomic():
            cam.position = eye
            cam.look_at = look

    def set_extent(self, points: list) -> None:
        """Frame these points (a recorded sortie's whole trajectories) in "fit engagement"
        and "top", now and for viewers who connect later."""
        self._extent = np.asarray(points, dtype=float).reshape(-1, 3)
        self._refit()

    def _refit(self) -> None:
        clients = self.server.get_clients()
        for cid, dd in list(self._views.items()):
            if cid in clients and dd.value in ("fit engagement", "top"):
                self._apply_static_view(clients[cid], dd.value)

    def _fit_bounds(self, points: list) -> None:
        if len(points) < 1:
            return
        p = np.asarray(points, dtype=float)
        lo, hi = p.min(axis=0), p.max(axis=0)
        if self._bounds is not None:
            lo, hi = np.minimum(lo, self._bounds[0]), np.maximum(hi, self._bounds[1])
        self._bounds = (lo, hi)
        if self._extent_fixed:
            return
        self._extent = p  # the trails so far (each call has them whole)

    def clear(self) -> None:
        """Remove everything a sortie added (the grid stays)."""
        for handle in self._handles:
            handle.remove()
        self._handles = []
        self._vehicle = self._target = self._frustum = None
        self._trail_time_s = -1.0
        self._shown = None
        self._bounds = None
        self._extent, self._extent_fixed = None, False

    def reset(
        self, cam: CameraModel, diameter_m: float, state: SceneState, extent: list | None = None
    ) -> None:
        """A new sortie; ``extent``: its whole trajectories when known (a recorded one)."""
        self.clear()
        self._closest_shown = self._fitted_done = False
        if extent is not None and len(extent) >= 2:
            self._extent, self._extent_fixed = np.asarray(extent, dtype=float), True
            self._refit()
        s = self.server.scene
        self._vehicle = s.add_frame("/vehicle", axes_length=1.2, axes_radius=0.05)
        self._frustum = s.add_camera_frustum(
            "/vehicle/camera",
            fov=math.radians(cam.vfov_deg),
            aspect=cam.width_px / cam.height_px,
            scale=0.9,
            color=(20, 20, 20),
            wxyz=tuple(rotmat_to_quat(cam.R_BC)),
            cast_shadow=False,
        )
        self._diameter = diameter_m
        self._target = s.add_icosphere(
            "/target",
            radius=self._diameter / 2.0,
            color=TARGET_RGB,
            cast_shadow=False,
            receive_shadow=False,
        )
        labels = [
            s.add_label("/vehicle/label", "interceptor", position=(0.0, 0.0, 0.8)),
            s.add_label("/target/label", "target", position=(0.0, 0.0, -0.6)),
        ]
        self._labels = labels
        # lines are created once and then only their points change: re-adding a node would
        # rebuild its geometry in every viewer
        vp, tp = np.array(state.vehicle_p, np.float32), np.array(state.target_p, np.float32)
        self._los = s.add_line_segments(
            "/los", np.array([[vp, tp]]), colors=LOS_RGB, thickness=2.0, thickness_units="screen"
        )
        self._trails = {
            name: s.add_line_segments(
                name, np.array([[p, p]]), colors=rgb, thickness=3.0, thickness_units="screen"
            )
            for name, p, rgb in (
                ("/trail_vehicle", vp, TRAIL_VEHICLE_RGB),
                ("/trail_target", tp, TRAIL_TARGET_RGB),
            )
        }
        self._trail_rgb = {"/trail_vehicle": TRAIL_VEHICLE_RGB, "/trail_target": TRAIL_TARGET_RGB}
        self._handles = [
            *labels,
            self._frustum,
            self._vehicle,
            self._target,
            self._los,
            *self._trails.values(),
        ]
        self.update(state, [], [])

    @staticmethod
    def _segments(points: list[list[float]]) -> np.ndarray | None:
        if len(points) < 2:
            return None
        p = np.asarray(points, dtype=np.float32)
        return np.stack([p[:-1], p[1:]], axis=1)

    def update(self, state: SceneState, trail_vehicle, trail_target) -> None:
        if self._vehicle is None:
            return
        shown = (state, len(trail_vehicle), len(trail_target))
        if shown == self._shown:
            return  # an idle, paused or finished session publishes the same scene again
        self._shown = shown
        s = self.server.scene
        vp = np.array(state.vehicle_p)
        tp = np.array(state.target_p)
        done = state.closest_point is not None
        t = state.time_s
        trails_due = done or abs(t - self._trail_time_s) >= 0.5 or t < 0.05
        with self.server.atomic():
            self._vehicle.position = vp
            self._vehicle.wxyz = np.array(state.vehicle_q)
            self._target.position = tp
            self._los.points = np.array([[vp, tp]], dtype=np.float32)
            if trails_due:
                self._trail_time_s = t
                for name, pts, end in (
                    ("/trail_vehicle", trail_vehicle, vp),
                    ("/trail_target", trail_target, tp),
                ):
                    seg = self._segments([*pts, list(end)])
                    if seg is not None:
                        handle = self._trails[name]
                        handle.points = seg
                        handle.colors = np.broadcast_to(
                            np.array(self._trail_rgb[name], np.uint8), seg.shape
                        ).copy()
            if done and not self._closest_shown:
                self._closest_shown = True
                # above the whole engagement, straight over the meeting point, with a leader
                # line down to it: clear of the vehicle, which is there
                cp = np.array(state.closest_point, dtype=float)
                lo, hi = self._bounds if self._bounds is not None else (cp, cp)
                size = float(max(np.max(hi - lo), 2.0))
                top = cp.copy()
                top[2] = max(float(hi[2]), float(cp[2])) + 0.15 * size
                label = s.add_label("/closest_label", state.outcome_label, position=tuple(top))
                leader = s.add_line_segments(
                    "/closest_leader",
                    np.array([[cp, top]], dtype=np.float32),
                    colors=(0, 150, 0),
                    thickness=1.5,
                    thickness_units="screen",
                )
                self._handles = [leader, *self._handles]
                marker = s.add_icosphere(
                    "/closest",
                    radius=0.08,
                    color=(0, 200, 0),
                    position=state.closest_point,
                    cast_shadow=False,
                    receive_shadow=False,
                )
                self._handles = [label, marker, *self._handles]
                for name_label in self._labels:  # they meet there: one label, the outcome
                    name_label.visible = False
        if trails_due:
            self._fit_bounds([*trail_vehicle, *trail_target, list(vp), list(tp)])
        if done and self._closest_shown and not self._fitted_done:
            self._fitted_done = True
            self._refit()  # the whole engagement, now known
        moving = [(cid, dd.value) for cid, dd in list(self._views.items())]
        if not any(v in ("follow vehicle", "chase") for _, v in moving):
            return
        R = quat_to_rotmat(state.vehicle_q)
        clients = self.server.get_clients()
        for cid, preset in moving:
            client = clients.get(cid)
            if client is None:
                continue
            if preset == "follow vehicle":  # behind and above, north-up: the world stays put
                eye, look = vp + np.array([-3.0, -6.0, 3.0]), vp
            elif preset == "chase":  # behind the vehicle along its nose
                eye, look = vp - 4.0 * R[:, 0] + np.array([0.0, 0.0, 1.5]), vp + 3.0 * R[:, 0]
            else:
                continue
            client.camera.position = eye
            client.camera.look_at = look

    def overlay(self, trail_vehicle: list, trail_target: list) -> None:
        """Another sortie's trails (grey), to compare with the one shown."""
        s = self.server.scene
        for name, pts, rgb in (
            ("/compare/vehicle", trail_vehicle, COMPARE_VEHICLE_RGB),
            ("/compare/target", trail_target, COMPARE_TARGET_RGB),
        ):
            seg = self._segments(pts)
            if seg is not None:
                self._handles.append(
                    s.add_line_segments(
                        name, seg, colors=rgb, thickness=2.0, thickness_units="screen"
                    )
                )
