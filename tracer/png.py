# SPDX-License-Identifier: GPL-3.0-or-later
"""8-bit sRGB PNG from linear premultiplied RGBA, with numpy and zlib only."""
import struct
import zlib

import numpy as np

from hairio import atomic_write


def linear_to_srgb(x):
    """The sRGB transfer function (IEC 61966-2-1), for linear values in [0, 1]."""
    x = np.clip(np.asarray(x, np.float64), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def to_srgb8(rgba):
    """(H, W, 4) linear premultiplied RGBA -> (H, W, 4) uint8 straight-alpha sRGB (PNG's kind)."""
    rgba = np.asarray(rgba, np.float64)
    alpha = np.clip(rgba[..., 3], 0.0, 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        straight = np.where(alpha[..., None] > 0, rgba[..., :3] / alpha[..., None], 0.0)
    out = np.empty(rgba.shape[:2] + (4,), np.uint8)
    out[..., :3] = np.round(linear_to_srgb(straight) * 255)
    out[..., 3] = np.round(alpha * 255)
    return out


def encode_png(rgba8):
    """PNG bytes of an (H, W, 4) uint8 array (colour type 6, 8 bits, filter 0 on every row)."""
    h, w, _ = rgba8.shape
    raw = np.zeros((h, 1 + 4 * w), np.uint8)
    raw[:, 1:] = rgba8.reshape(h, 4 * w)

    def chunk(kind, data):
        return (struct.pack(">I", len(data)) + kind + data
                + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF))

    return (b"\x89PNG\r\n\x1a\n"
            + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 6, 0, 0, 0))
            + chunk(b"sRGB", b"\x00")
            + chunk(b"IDAT", zlib.compress(raw.tobytes(), 6))
            + chunk(b"IEND", b""))


def write_png(path, rgba):
    """Write linear premultiplied float RGBA (H, W, 4) as an sRGB PNG, all or nothing."""
    data = encode_png(to_srgb8(rgba))
    with atomic_write(path) as f:
        f.write(data)
