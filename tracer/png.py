# SPDX-License-Identifier: GPL-3.0-or-later
"""8-bit sRGB PNG from linear premultiplied RGBA, with numpy and zlib only."""
import pathlib
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


def _chunk(kind, data):
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)


def _png_head(w, h):
    return b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 6, 0, 0, 0)) + _chunk(b"sRGB", b"\x00")


def _filtered_rows(rgba8):
    """PNG scanlines of an (h, w, 4) uint8 array: filter byte 0, then the row."""
    h, w, _ = rgba8.shape
    raw = np.zeros((h, 1 + 4 * w), np.uint8)
    raw[:, 1:] = rgba8.reshape(h, 4 * w)
    return raw.tobytes()


def encode_png(rgba8):
    """PNG bytes of an (H, W, 4) uint8 array (colour type 6, 8 bits, filter 0 on every row)."""
    h, w, _ = rgba8.shape
    return (_png_head(w, h) + _chunk(b"IDAT", zlib.compress(_filtered_rows(rgba8), 6))
            + _chunk(b"IEND", b""))


def write_png(path, rgba):
    """Write linear premultiplied float RGBA (H, W, 4) as an sRGB PNG, all or nothing."""
    data = encode_png(to_srgb8(rgba))
    with atomic_write(path) as f:
        f.write(data)


def write_png_bands(path, width, height, bands):
    """Write an sRGB PNG of `width` x `height` from `bands`, an iterable of (h, width, 4)
    uint8 row bands from the top that add up to `height` rows: each band is compressed
    and written as it comes, so an image far larger than memory can be written. All or
    nothing, like write_png; the pixels decode to what encode_png would store."""
    rows = 0
    z = zlib.compressobj(6)
    with atomic_write(path) as f:
        f.write(_png_head(width, height))
        for band in bands:
            band = np.asarray(band, np.uint8)
            if band.ndim != 3 or band.shape[1:] != (width, 4):
                raise ValueError(f"band of shape {band.shape}; expected (rows, {width}, 4)")
            rows += len(band)
            data = z.compress(_filtered_rows(band))
            if data:
                f.write(_chunk(b"IDAT", data))
        if rows != height:
            raise ValueError(f"bands hold {rows} rows; the image has {height}")
        f.write(_chunk(b"IDAT", z.flush()) + _chunk(b"IEND", b""))


def read_png_rgba8(path):
    """The (H, W, 4) uint8 pixels of a PNG file this module wrote (decode_png_rgba8)."""
    return decode_png_rgba8(pathlib.Path(path).read_bytes(), name=str(path))


def decode_png_rgba8(data, name="PNG data"):
    """The (H, W, 4) uint8 pixels of PNG bytes as this module writes them (8-bit RGBA, filter
    0 rows), for tests and tools that check what was written; any other PNG, or a chunk whose
    CRC does not match, is refused (ValueError naming `name`)."""
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise ValueError(f"{name}: not a PNG file")
    pos, idat, size = 8, [], None
    while pos + 8 <= len(data):
        (n,) = struct.unpack(">I", data[pos:pos + 4])
        kind, body = data[pos + 4:pos + 8], data[pos + 8:pos + 8 + n]
        (crc,) = struct.unpack(">I", data[pos + 8 + n:pos + 12 + n])
        if zlib.crc32(kind + body) & 0xFFFFFFFF != crc:
            raise ValueError(f"{name}: the {kind!r} chunk's CRC does not match")
        if kind == b"IHDR":
            w, h, depth, colour = struct.unpack(">IIBB", body[:10])
            if (depth, colour) != (8, 6):
                raise ValueError(f"{name}: {depth}-bit colour type {colour}; expected 8-bit RGBA")
            size = (h, w)
        elif kind == b"IDAT":
            idat.append(body)
        pos += 12 + n
    if size is None:
        raise ValueError(f"{name}: no IHDR chunk")
    h, w = size
    raw = np.frombuffer(zlib.decompress(b"".join(idat)), np.uint8).reshape(h, 1 + 4 * w)
    if raw[:, 0].any():
        raise ValueError(f"{name}: filtered rows; this reader takes filter 0 only")
    return raw[:, 1:].reshape(h, w, 4)
