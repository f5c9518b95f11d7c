"""The simulator flies the same sorties as the reference: each case's outcome, miss, intercept
time, terminal speed, peak normal acceleration, detection counts and the vehicle's final state
match tests/data/speed_reference.json (written by tests/speed_reference.py) to within 1e-9
(absolute, or relative for values above 1), so a change made for speed cannot change what is
flown."""

from __future__ import annotations

import json
import math

import pytest

from tests.speed_reference import CASES, REFERENCE_PATH, compute

TOL = 1e-9

REFERENCE = {tuple(row["case"]): row["result"] for row in json.loads(REFERENCE_PATH.read_text())}


def test_reference_covers_the_cases():
    assert set(REFERENCE) == set(CASES)


@pytest.mark.parametrize("case", CASES, ids=lambda c: "-".join(map(str, c)))
def test_sortie_matches_reference(case):
    ref, got = REFERENCE[case], compute(case)
    assert got.keys() == ref.keys()
    for key, want in ref.items():
        have = got[key]
        if isinstance(want, (float, list)):
            wants = want if isinstance(want, list) else [want]
            haves = have if isinstance(have, list) else [have]
            for w, h in zip(wants, haves, strict=True):
                assert math.isclose(h, w, rel_tol=TOL, abs_tol=TOL), (key, h, w)
        else:
            assert have == want, key
