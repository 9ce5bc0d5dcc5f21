# SPDX-License-Identifier: GPL-3.0-or-later
"""Colour held a strand at a time (Strands.strand_color): what it gives is what the same
colour a point gives, to every reader of the strands and every file format."""
import numpy as np
import pytest

from hairio import InputError, Strands
from hairio.formats import read_strands, write_strands
from hairio.formats.registry import FORMATS
from hairio_scenes import make_wavy


def _pair(seed=3):
    """(colour a strand, the same colour a point) of one set of wavy strands."""
    s = make_wavy(40, seed=seed)
    rgb = np.random.default_rng(seed).uniform(0.05, 0.95, (s.num_strands, 3)).astype(np.float32)
    held = Strands.from_arrays(s.points, s.counts, s.radius, None, s.alpha, s.wisp, strand_color=rgb)
    pointwise = Strands.from_arrays(s.points, s.counts, s.radius, np.repeat(rgb, s.counts, axis=0), s.alpha, s.wisp)
    return held, pointwise


def test_colour_a_strand_is_each_strands_colour_at_its_points_made_once():
    held, pointwise = _pair()
    assert held.point_color is None
    color = held.color
    np.testing.assert_array_equal(color, pointwise.color)
    assert color.dtype == np.float32 and color.flags.c_contiguous
    assert held.color is color      # kept: made once
    for s in (held.with_guides(root_uv=np.zeros((held.num_strands, 2))),):
        assert s.strand_color is held.strand_color


def test_colour_a_strand_is_checked_and_not_given_twice():
    s = make_wavy(10)
    with pytest.raises(InputError, match="strand_color"):
        Strands.from_arrays(s.points, s.counts, strand_color=np.zeros((s.num_strands + 1, 3)))
    with pytest.raises(InputError, match="color and strand_color"):
        Strands.from_arrays(s.points, s.counts, color=np.zeros((s.num_points, 3)),
                            strand_color=np.zeros((s.num_strands, 3)))
    with pytest.raises(InputError, match="strand_color"):
        Strands.from_arrays(s.points, s.counts, strand_color=np.full((s.num_strands, 3), 1e39))


@pytest.mark.parametrize("fmt", FORMATS, ids=lambda f: f.name)
def test_every_format_writes_a_colour_a_strand_as_the_same_colour_a_point(tmp_path, fmt):
    held, pointwise = _pair()
    outcomes = []
    for name, s in (("held", held), ("pointwise", pointwise)):
        path = tmp_path / (name + fmt.extension)
        try:
            write_strands(path, s)
        except InputError as e:
            outcomes.append(("refused", str(e).replace(name, "")))
            continue
        back = read_strands(path)
        outcomes.append(("written", back))
    assert outcomes[0][0] == outcomes[1][0]
    if outcomes[0][0] == "refused":
        assert outcomes[0][1] == outcomes[1][1]
        return
    a, b = outcomes[0][1], outcomes[1][1]
    for name in ("points", "counts", "radius", "color", "alpha"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
