# SPDX-License-Identifier: GPL-3.0-or-later
"""Where the rays of each pixel go: the trace shader's main (tracer/shaders/trace_main.glsl),
the same sample positions from the same integer hash."""
import numpy as np


def _hash32(x):
    x = x.astype(np.uint32)
    x ^= x >> np.uint32(16)
    x *= np.uint32(0x7FEB352D)
    x ^= x >> np.uint32(15)
    x *= np.uint32(0x846CA68B)
    x ^= x >> np.uint32(16)
    return x


def _unit(h):
    """A number in [0, 1) from a hash's top 24 bits (the shader's unit_of)."""
    return (h >> np.uint32(8)).astype(np.float64) / 16777216.0


def _grid(width, height, spp_n, origin):
    """Per sample, shape (H, W, spp_n²): its column and row in this image, its index, and its
    column and row in the whole image of which this one is the window at `origin`."""
    py, px, s = np.meshgrid(np.arange(height), np.arange(width), np.arange(spp_n * spp_n), indexing="ij")
    gx, gy = (px + int(origin[0])).astype(np.uint32), (py + int(origin[1])).astype(np.uint32)
    return px, py, s, gx, gy


def _pixel_hash(s, gx, gy, seed=0):
    """The shader's hash of (sample, row, column) and `seed` (sample_jitter's, seed 0, and
    pixel_hash's)."""
    return _hash32(_hash32(_hash32(s.astype(np.uint32) ^ np.uint32(seed)) ^ gy) ^ gx)


def sample_positions(width, height, spp_n, origin=(0, 0)):
    """Continuous pixel coordinates (x from the left, y from the top) of every sample,
    shape (H, W, spp_n², 2): pixel centres for one sample, otherwise one jittered sample per
    stratum, jittered by the shader's hash of (sample, row, column), the row and column in
    the whole image of which this one is the window at `origin` (Camera.pixel_origin)."""
    px, py, s, gx, gy = _grid(width, height, spp_n, origin)
    if spp_n == 1:
        jx = np.full(px.shape, 0.5)
        jy = np.full(px.shape, 0.5)
    else:
        h = _pixel_hash(s, gx, gy)
        jx = ((s % spp_n) + _unit(h)) / spp_n
        jy = ((s // spp_n) + _unit(_hash32(h ^ np.uint32(0x68BC21EB)))) / spp_n
    return np.stack([px + jx, py + jy], axis=-1)


def _pick(per_sample, camera, pixels):
    """(H, W, S, ...) per-sample values -> those of the whole image, row by row (pixels None),
    or of the pixels (P,2) int columns x, y, checked to lie inside the image."""
    w, h = camera.size
    if pixels is None:
        return per_sample.reshape((-1,) + per_sample.shape[3:])
    px = np.asarray(pixels, np.int64)
    if px.ndim != 2 or px.shape[1] != 2 or (px < 0).any() or (px[:, 0] >= w).any() or (px[:, 1] >= h).any():
        raise ValueError(f"pixels: expected (P, 2) integer x, y inside {w}x{h}, got shape {px.shape}")
    return per_sample[px[:, 1], px[:, 0]].reshape((-1,) + per_sample.shape[3:])


def pixel_samples(camera, spp_n, pixels=None):
    """Sample positions (P·spp_n², 2) of the whole image (pixels None: P = W·H, row by row)
    or of the pixels (P,2) int columns x, y; the same samples as the GPU's for those pixels."""
    w, h = camera.size
    return _pick(sample_positions(w, h, spp_n, camera.pixel_origin), camera, pixels)


def finish_pixels(rgba, camera, spp_n, pixels=None):
    """Per-sample RGBA (P·spp_n², 4) -> the image (H, W, 4), or (P, 4) for `pixels`."""
    w, h = camera.size
    shape = (h, w) if pixels is None else (len(pixels),)
    return rgba.reshape(shape + (spp_n * spp_n, 4)).mean(axis=-2)


def light_seeds(camera, spp_n, pixels=None):
    """Per sample (in pixel_samples' order) the shader's light_seed: pixel_hash of 0x27d4eb2d,
    which its points on lights are drawn from (trace_main.glsl's main)."""
    w, h = camera.size
    _, _, s, gx, gy = _grid(w, h, spp_n, camera.pixel_origin)
    return _pick(_pixel_hash(s, gx, gy, 0x27D4EB2D), camera, pixels)


def light_sample(seeds, k, l, num_lights):
    """(N, 2): the shader's light_sample(k, l) for each sample's seed."""
    h = _hash32(seeds ^ np.uint32(k * num_lights + l + 1))
    return np.stack([_unit(h), _unit(_hash32(h ^ np.uint32(0x68BC21EB)))], axis=1)
