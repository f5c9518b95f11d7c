"""What the simulated vehicle believes, kept apart from what is true (docs/realism.md).

:func:`loop_configuration` is everything the onboard loop is constructed with, built from the
scenario's ``[belief]`` table, its ``[gains]`` and the frame size the camera delivers, and
from nothing else: the true target size, camera, airframe and estimate errors never reach it.
:func:`true_camera` is the camera the simulator flies (``[camera]``)."""

from __future__ import annotations

from dataclasses import dataclass

from onboard.camera_model import CameraModel
from onboard.datatypes import VehicleParams
from onboard.enums import DEFAULT_LAW
from onboard.estimation.dkf import DkfConfig
from onboard.gains import Gains

from ..scenario import Scenario


@dataclass(frozen=True)
class LoopConfiguration:
    """The arguments of :class:`~onboard.loop.InterceptionLoop`."""

    camera: CameraModel
    vehicle: VehicleParams
    gains: Gains
    law: str
    control_rate_hz: float
    dkf: DkfConfig


def true_camera(scenario: Scenario) -> CameraModel:
    """The camera as it is: ``[camera]``'s lens, principal point, mount and offset."""
    c = scenario.camera
    return CameraModel(
        c.width_px,
        c.height_px,
        c.hfov_deg,
        c.mount_pitch_deg,
        c.mount_roll_deg,
        principal_offset_px=(c.principal_offset_u_px, c.principal_offset_v_px),
        distortion=(c.k1, c.k2, c.p1, c.p2),
        offset_b_m=c.offset_m,
    )


def believed_camera(scenario: Scenario) -> CameraModel:
    """The operator's calibration of the camera (``[belief]``) for the frame size the camera
    delivers (the frame's size is seen, not believed)."""
    b, c = scenario.belief, scenario.camera
    return CameraModel(
        c.width_px,
        c.height_px,
        b.camera_hfov_deg,
        b.camera_mount_pitch_deg,
        b.camera_mount_roll_deg,
        principal_offset_px=(b.camera_principal_offset_u_px, b.camera_principal_offset_v_px),
        distortion=(b.camera_k1, b.camera_k2, b.camera_p1, b.camera_p2),
        offset_b_m=b.camera_offset_m,
    )


def loop_configuration(
    scenario: Scenario, law: str = DEFAULT_LAW.value, gains: Gains | None = None
) -> LoopConfiguration:
    """Everything the loop is built with for ``scenario``: the believed camera, the believed
    hover thrust (as the onboard runtime builds it from ``PRG_HOVER_THR``), the gains (the
    operator's drag and lag compensation among them), the believed target diameter."""
    b = scenario.belief
    return LoopConfiguration(
        camera=believed_camera(scenario),
        vehicle=VehicleParams.from_hover_thrust(b.hover_thrust),
        gains=gains if gains is not None else scenario.gains_obj(),
        law=law,
        control_rate_hz=float(scenario.sim.control_rate_hz),
        dkf=DkfConfig(target_diameter_m=b.target_diameter_m),
    )
