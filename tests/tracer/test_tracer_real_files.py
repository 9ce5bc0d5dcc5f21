# SPDX-License-Identifier: GPL-3.0-or-later
"""Real hair from other tools renders with plausible coverage."""
import numpy as np
import pytest

from hairio import Strands
from tracer import Camera, RenderSettings


@pytest.mark.parametrize("name", ["straight.hair", "Ratboy_mohawk.tfx", "sintel_hair.tfx", "harolongo.data"])
def test_real_file_renders_with_plausible_coverage(renderer, shared_data, name):
    from hairio.formats import read_strands
    strands = read_strands(str(shared_data / name))
    lo, hi = strands.bounds()
    # Not every format stores thickness: give every file a human hair's proportion (about
    # 1/3000 of the hairdo) and let minimum pixel width keep it visible at 64 pixels.
    strands = Strands.from_arrays(strands.points, strands.counts, radius=np.full(strands.num_points,
                                  float(np.linalg.norm(hi - lo)) / 3000), color=strands.color)
    renderer.set_strands(strands)
    settings = RenderSettings(shadows=True, min_pixel_width=True, min_pixel_width_cap=8.0)
    img = renderer.render(Camera.frame_bounds(lo, hi, (64, 64)), settings)
    assert np.all(np.isfinite(img))
    coverage = float(np.mean(img[..., 3] > 0))
    # framed to the bounding sphere: hair fills part of the frame, never none or all of it
    assert 0.02 < coverage < 0.9, coverage
    lit = img[..., :3][img[..., 3] > 0]
    # Shaded, not black: lit beyond what the ambient term alone can give (physically based
    # dark-brown hair under the default unit sun is dark, so no fixed brightness is asked).
    assert lit.max() > settings.ambient * strands.color.max()
