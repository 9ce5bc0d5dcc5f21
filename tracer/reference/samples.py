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


def sample_positions(width, height, spp_n, origin=(0, 0)):
    """Continuous pixel coordinates (x from the left, y from the top) of every sample,
    shape (H, W, spp_n², 2): pixel centres for one sample, otherwise one jittered sample per
    stratum, jittered by the shader's hash of (sample, row, column), the row and column in
    the whole image of which this one is the window at `origin` (Camera.pixel_origin)."""
    py, px, s = np.meshgrid(np.arange(height), np.arange(width), np.arange(spp_n * spp_n), indexing="ij")
    if spp_n == 1:
        jx = np.full(px.shape, 0.5)
        jy = np.full(px.shape, 0.5)
    else:
        gx, gy = (px + int(origin[0])).astype(np.uint32), (py + int(origin[1])).astype(np.uint32)
        h = _hash32(_hash32(_hash32(s.astype(np.uint32)) ^ gy) ^ gx)
        rx = (h >> np.uint32(8)).astype(np.float64) / 16777216.0
        ry = (_hash32(h ^ np.uint32(0x68BC21EB)) >> np.uint32(8)).astype(np.float64) / 16777216.0
        jx = ((s % spp_n) + rx) / spp_n
        jy = ((s // spp_n) + ry) / spp_n
    return np.stack([px + jx, py + jy], axis=-1)


def pixel_samples(camera, spp_n, pixels=None):
    """Sample positions (P·spp_n², 2) of the whole image (pixels None: P = W·H, row by row)
    or of the pixels (P,2) int columns x, y; the same samples as the GPU's for those pixels."""
    w, h = camera.size
    pos = sample_positions(w, h, spp_n, camera.pixel_origin)
    if pixels is None:
        return pos.reshape(-1, 2)
    px = np.asarray(pixels, np.int64)
    if px.ndim != 2 or px.shape[1] != 2 or (px < 0).any() or (px[:, 0] >= w).any() or (px[:, 1] >= h).any():
        raise ValueError(f"pixels: expected (P, 2) integer x, y inside {w}x{h}, got shape {px.shape}")
    return pos[px[:, 1], px[:, 0]].reshape(-1, 2)


def finish_pixels(rgba, camera, spp_n, pixels=None):
    """Per-sample RGBA (P·spp_n², 4) -> the image (H, W, 4), or (P, 4) for `pixels`."""
    w, h = camera.size
    shape = (h, w) if pixels is None else (len(pixels),)
    return rgba.reshape(shape + (spp_n * spp_n, 4)).mean(axis=-2)


def light_seeds(camera, spp_n, pixels=None):
    """Per sample (in pixel_samples' order) the shader's light_seed: the hash of (sample,
    row, column, 0x27d4eb2d) its points on lights are drawn from (trace_main.glsl's main)."""
    w, h = camera.size
    py, px, s = np.meshgrid(np.arange(h), np.arange(w), np.arange(spp_n * spp_n), indexing="ij")
    gx = (px + int(camera.pixel_origin[0])).astype(np.uint32)
    gy = (py + int(camera.pixel_origin[1])).astype(np.uint32)
    seeds = _hash32(_hash32(_hash32(s.astype(np.uint32) ^ np.uint32(0x27D4EB2D)) ^ gy) ^ gx)
    if pixels is None:
        return seeds.reshape(-1)
    px_ = np.asarray(pixels, np.int64)
    return seeds[px_[:, 1], px_[:, 0]].reshape(-1)


def light_sample(seeds, k, l, num_lights):
    """(N, 2): the shader's light_sample(k, l) for each sample's seed."""
    h = _hash32(seeds ^ np.uint32(k * num_lights + l + 1))
    u0 = (h >> np.uint32(8)).astype(np.float64) / 16777216.0
    u1 = (_hash32(h ^ np.uint32(0x68BC21EB)) >> np.uint32(8)).astype(np.float64) / 16777216.0
    return np.stack([u0, u1], axis=1)
