"""Target detectors: BGR frame in, :class:`~onboard.datatypes.Detection` (or nothing) out."""

from .detector import Detector, RedBalloonConfig, RedBalloonDetector, RoiStats

__all__ = ["Detector", "RedBalloonConfig", "RedBalloonDetector", "RoiStats"]
