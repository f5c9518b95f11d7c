"""The gains rule of the simulator (docs/operator-gains.md): the operator's gains are a gain
set (the defaults or a loaded named set) plus the edits the operator applied; a plain Start
flies them, or, when the scenario has a ``[gains]`` table, that table (the edits are then
dropped and the note names them). A re-fly or a study trial flies gains given for that sortie
only: the operator's gain set and edits are left as they were, and the next plain Start flies
them again."""

from __future__ import annotations

from dataclasses import dataclass

from onboard.gains import Gains

from ..scenario import Scenario


@dataclass(frozen=True)
class FlownGains:
    """The gains a sortie flies, the set they start from, its name, and a note for the page."""

    gains: Gains
    base: Gains
    source: str
    note: str | None = None


class OperatorGains:
    """The operator's gain set and applied edits (name -> value)."""

    def __init__(self) -> None:
        self.gain_set = Gains()
        self.source = "defaults"
        self.edits: dict[str, float] = {}

    def in_force(self) -> FlownGains:
        """What a plain Start of a scenario without ``[gains]`` flies."""
        return FlownGains(self.gain_set.replace(**self.edits), self.gain_set, self.source)

    def for_start(
        self,
        scenario: Scenario,
        sortie_gains: Gains | None = None,
        sortie_source: str | None = None,
    ) -> FlownGains:
        """The gains a Start flies (module docstring); ``sortie_gains``: that sortie's own."""
        if sortie_gains is not None:  # this sortie's own gains: the operator's stay put
            return FlownGains(sortie_gains, sortie_gains, sortie_source or "given for this sortie")
        if scenario.gains:  # the scenario has a [gains] table: it replaces the edits
            dropped = sorted(self.edits)
            self.edits = {}
            base = scenario.gains_obj()
            note = f"scenario {scenario.name} carries its own gains ([gains])" + (
                f"; your edits to {', '.join(dropped)} were replaced" if dropped else ""
            )
            return FlownGains(base, base, f"scenario {scenario.name}", note)
        return self.in_force()

    def load(self, gains: Gains, source: str) -> None:
        """A named gain set becomes the operator's, without edits."""
        self.gain_set, self.source, self.edits = gains, source, {}

    def take_edits(self, old: Gains, new: Gains, base: Gains) -> None:
        """The values changed from ``old`` to ``new`` are the operator's edits, except those
        back at the value the sortie started with (``base``), which are dropped."""
        start = base.to_dict()
        for k, v in new.to_dict().items():
            if v == getattr(old, k):
                continue
            if v == start[k]:
                self.edits.pop(k, None)
            else:
                self.edits[k] = v

    def drop_edits(self) -> None:
        self.edits = {}
