# SPDX-License-Identifier: GPL-3.0-or-later
"""Randomised scenes (hypothesis) over scales 1e-3…1e3, offsets up to 1e4 × the scene scale
(the SPEC §9 range), and degenerate keys and triangles: groom → tracer → pixels end finite
and agree with the float64 reference, or stop at a clear InputError."""
from hypothesis import HealthCheck, given, settings

from benchmarks import stress_cases as sc


@settings(max_examples=25, deadline=None, database=None, derandomize=True,
          suppress_health_check=list(HealthCheck))
@given(sc.random_scene_strategy(spec_range_only=True))
def test_random_scene_is_finite_or_a_clear_error(spec):
    outcome = sc.run_random_scene(spec)
    assert outcome.ok, f"{outcome.kind}: {outcome.detail} (scene {spec})"
