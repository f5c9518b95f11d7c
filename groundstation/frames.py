"""Re-exported from :mod:`onboard.frames`, where the sortie's frame and its observers are
defined (the onboard runtime builds frames too)."""

from onboard.frames import Frame, FrameList, SortieEvent, SortieObserver, SortieStart, Vec3

__all__ = ["Frame", "FrameList", "SortieEvent", "SortieObserver", "SortieStart", "Vec3"]
