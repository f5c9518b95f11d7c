"""Target detectors: BGR frame in, :class:`~onboard.datatypes.Detection` (or nothing) out."""

from .detector import Detector, RedBalloonDetector

__all__ = ["Detector", "RedBalloonDetector"]
