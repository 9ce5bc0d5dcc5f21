# SPDX-License-Identifier: GPL-3.0-or-later
"""SPEC §9 stress cases end to end across groom, tracer and hairio: each gives finite,
plausible output (checked against the float64 reference) or a clear InputError — never a
silently wrong result. The checks are defined in benchmarks/stress_cases.py, shared with the
benchmark report so both count the same thing."""
import numpy as np
import pytest

from benchmarks import stress_cases as sc

CASES = dict(sc.spec_cases())
# Bad input must be refused, not repaired in silence.
MUST_REFUSE = {"NaN in strand points", "Inf in strand radius", "NaN in scalp vertices", "NaN in key strand points"}
# Everything else is valid input and must give pixels.
MUST_RENDER = set(CASES) - MUST_REFUSE


@pytest.mark.parametrize("name", sorted(MUST_RENDER))
def test_valid_stress_input_gives_finite_checked_output(name):
    outcome = CASES[name]()
    assert outcome.kind == sc.FINITE, f"{name}: {outcome.kind}: {outcome.detail}"


@pytest.mark.parametrize("name", sorted(MUST_REFUSE))
def test_nan_or_inf_input_is_refused_with_a_message_naming_it(name):
    outcome = CASES[name]()
    assert outcome.kind == sc.CLEAR_ERROR, f"{name}: {outcome.kind}: {outcome.detail}"


def test_visible_hair_is_visible_and_matches_the_reference():
    """The checks themselves can fail: the crown case must cover pixels and agree with float64."""
    outcome = CASES["root on the crown / central line"]()
    assert outcome.kind == sc.FINITE
    assert outcome.checks["coverage"] > 0
    assert outcome.checks["coverage_agree"] >= sc.COVERAGE_MIN_AGREE


def test_silent_errors_are_detected():
    """A strand moved off its root, NaN pixels and an over-long strand are each reported."""
    from hairio import Strands
    pts = np.array([[0, 0, 0], [0, 0, 1.0], [1, 0, 0], [1, 0, 1.0]])
    s = Strands.from_arrays(pts, [2, 2])
    assert sc.strand_problems(s, roots=pts[[0, 2]]) == []
    assert any("leave their roots" in p for p in sc.strand_problems(s, roots=pts[[0, 2]] + [0, 0, 0.1]))
    assert any("long" in p for p in sc.strand_problems(s, max_length=0.5))
    img = np.zeros((4, 4, 4), np.float32)
    assert any("empty" in p for p in sc.image_problems(img, expect_visible=True))
    img[1, 1, 0] = np.nan
    assert any("NaN" in p for p in sc.image_problems(img, expect_visible=False))
