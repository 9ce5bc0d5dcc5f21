# SPDX-License-Identifier: GPL-3.0-or-later
"""Switches the tracer has no public setting for, turned from outside for measurement only.

The tracer chooses its grid resolution and always skips pixels outside the hair's screen
box and extra layers when all alpha is 1; to show what each choice is worth, the benchmark
replaces the one function that decides it, for the duration of a `with` block.
"""
import contextlib

import numpy as np

MAX_GRID_CELLS = 1 << 25     # 32 M cells: 256 MiB of cell table


@contextlib.contextmanager
def grid_scale(scale):
    """Build every grid (numpy or GPU build) with `scale` times the tracer's own cells per axis."""
    from tracer import grid as gmod
    original = gmod.grid_dims

    def scaled(box_size, extent, count=None, max_refs=None):
        d = np.asarray(original(box_size, extent, count, max_refs), np.float64) * scale
        # Keep the cell table within what a run can afford (the tracer caps its own choice too).
        over = np.prod(d) / MAX_GRID_CELLS
        if over > 1:
            d = d / over ** (1 / 3)
        return np.clip(np.round(d), 1, 1024).astype(np.int64)

    gmod.grid_dims = scaled
    try:
        yield
    finally:
        gmod.grid_dims = original


@contextlib.contextmanager
def no_screen_bounds(renderer):
    """Trace every pixel of the image, not only the hair's projected box."""
    def whole(camera):
        empty = not renderer.num_cylinders
        return None if empty else (0, 0, camera.size[0], camera.size[1])

    renderer.screen_bounds = whole
    try:
        yield
    finally:
        del renderer.screen_bounds


@contextlib.contextmanager
def all_layers(renderer):
    """Composite `settings.layers` layers even when every alpha is 1."""
    original = renderer.effective_layers
    renderer.effective_layers = lambda settings: settings.layers
    try:
        yield
    finally:
        del renderer.effective_layers
        assert renderer.effective_layers.__func__ is original.__func__
