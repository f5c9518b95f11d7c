"""The one rule for numbers shown to the operator: at most 4 significant digits, halves rounded
away from zero, no trailing zeros (0.006525 -> "0.006525", 12.3456 -> "12.35", 3.0 -> "3").
The page does the same in web/format.js (``String(Number(x.toPrecision(4)))``), so a value
reads the same in the header, the timeline, the 3D view and the sorties page."""

from __future__ import annotations

import math
from decimal import ROUND_HALF_UP, Decimal

SIGNIFICANT_DIGITS = 4


def fmt_num(x: float | None, missing: str = "—") -> str:
    """``x`` with at most :data:`SIGNIFICANT_DIGITS` significant digits (``missing`` for
    None, the words for NaN and infinities)."""
    if x is None:
        return missing
    x = float(x)
    if not math.isfinite(x):
        return "NaN" if math.isnan(x) else ("Infinity" if x > 0 else "-Infinity")
    if x == 0.0:
        return "0"
    d = Decimal(x)  # the exact binary value, as JavaScript's toPrecision rounds it
    exp = d.adjusted() - (SIGNIFICANT_DIGITS - 1)
    r = d.quantize(Decimal(1).scaleb(exp), rounding=ROUND_HALF_UP)
    text = format(r, "f")
    if "." in text:
        text = text.rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text
