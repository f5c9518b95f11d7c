"""Immutable values: what a copy of the loop may share with the loop (no numpy here: the
gains are read by ``groundstation scenarios`` and ``--help`` without it)."""

from __future__ import annotations

from typing import Self


class SharedWhenCopied:
    """For frozen dataclasses whose fields are immutable (numbers, tuples, read-only arrays):
    a copy of one, shallow or deep, is the object itself, as for a tuple. The rehearsal's
    shadow loop (a deep copy of the loop: onboard/runtime/rehearsal.py) then reads the very
    gains, camera model and configurations the loop reads, and leaves them in the caches for
    the tick (README "Session 21" under Measured)."""

    __slots__ = ()

    def __copy__(self) -> Self:
        return self

    def __deepcopy__(self, memo: dict) -> Self:
        return self
