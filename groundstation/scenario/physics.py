"""The physics a scenario is checked against: a tethered helium balloon's lift and mass, and
where a fan jet's speed can be set."""

from __future__ import annotations

import math

from onboard.constants import GRAVITY_M_S2

from .specs import TargetSpec, Vec3, WindSpec

AIR_DENSITY_KG_M3 = 1.2  # sea level, 20 C
HELIUM_DENSITY_KG_M3 = 0.166  # at 1 atm, 20 C (a party balloon's slight overpressure ignored)


def helium_gross_lift_n(diameter_m: float) -> float:
    """Buoyancy minus the helium's weight of a sphere (N): (rho_air - rho_He) V g."""
    volume = math.pi / 6.0 * diameter_m**3
    return (AIR_DENSITY_KG_M3 - HELIUM_DENSITY_KG_M3) * volume * GRAVITY_M_S2


def balloon_lift_and_mass(target: TargetSpec) -> tuple[float, float]:
    """(net lift N, effective mass kg) of a tethered helium balloon: the file's values, or
    where they are 0 the physics: net lift = (rho_air - rho_He) V g - m_envelope g; mass =
    m_envelope + rho_He V + rho_air V / 2, the last the added mass of a sphere accelerating in
    air (Lamb, *Hydrodynamics* §92; Newman, *Marine Hydrodynamics* §4.13). For the paper's
    0.16 m balloon with a 1.5 g envelope: 0.0071 N and 3.1 g."""
    volume = math.pi / 6.0 * target.diameter_m**3
    lift = target.net_lift_n or (
        helium_gross_lift_n(target.diameter_m) - target.envelope_mass_kg * GRAVITY_M_S2
    )
    mass = target.mass_kg or (
        target.envelope_mass_kg + HELIUM_DENSITY_KG_M3 * volume + 0.5 * AIR_DENSITY_KG_M3 * volume
    )
    return lift, mass


def jet_reference_problem(wind: WindSpec, reference_m: Vec3) -> str | None:
    """Why a fan jet cannot set its speed at ``reference_m`` (the target's rest position),
    or None: the point must be downstream of the fan."""
    m = wind.mean_m_s
    speed = math.sqrt(sum(c * c for c in m))
    if speed == 0.0:
        return None
    x = sum((reference_m[i] - wind.jet_source_m[i]) * m[i] for i in range(3)) / speed
    if x <= 0.0:
        return (
            "the fan must be upwind of the target: the target's rest position is "
            f"{-x:.2f} m behind the fan along wind.mean_m_s"
        )
    return None
