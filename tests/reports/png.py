"""A minimal PNG reader/writer (8-bit RGB/RGBA, non-interlaced) for screenshot checks, so the
browser test needs no imaging library."""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np


def read_png(path: Path) -> tuple[int, int, int, bytes]:
    """(width, height, channels, raw pixel bytes row by row)."""
    data = Path(path).read_bytes()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise ValueError(f"{path} is not a PNG file")
    pos, idat = 8, b""
    width = height = channels = 0
    while pos < len(data):
        (length,) = struct.unpack(">I", data[pos : pos + 4])
        kind = data[pos + 4 : pos + 8]
        body = data[pos + 8 : pos + 8 + length]
        pos += 12 + length
        if kind == b"IHDR":
            width, height, depth, color, _, _, interlace = struct.unpack(">IIBBBBB", body)
            if depth != 8 or color not in (2, 6) or interlace:
                raise ValueError(f"unsupported PNG (depth {depth}, colour type {color}, interlace {interlace})")
            channels = 3 if color == 2 else 4
        elif kind == b"IDAT":
            idat += body
        elif kind == b"IEND":
            break
    raw = np.frombuffer(zlib.decompress(idat), dtype=np.uint8).reshape(height, width * channels + 1)
    out = np.zeros((height, width * channels), dtype=np.uint8)
    prev = np.zeros(width * channels, dtype=np.uint8)
    for y in range(height):
        f, line = raw[y, 0], raw[y, 1:]
        if f == 0:
            cur = line.copy()
        elif f == 1:  # Sub: running sum per channel, mod 256
            cur = (np.cumsum(line.reshape(width, channels).astype(np.int64), axis=0) % 256).astype(np.uint8).reshape(-1)
        elif f == 2:  # Up
            cur = (line.astype(np.int64) + prev).astype(np.uint8)
        else:  # Average and Paeth depend on the reconstructed left pixel: one pixel at a time
            cur = _unfilter_slow(int(f), bytearray(line.tobytes()), prev.tobytes(), channels)
        out[y] = cur
        prev = cur
    return width, height, channels, out.tobytes()


def _unfilter_slow(f: int, line: bytearray, prev: bytes, channels: int) -> np.ndarray:
    for i in range(len(line)):
        a = line[i - channels] if i >= channels else 0
        b = prev[i]
        c = prev[i - channels] if i >= channels else 0
        if f == 3:
            line[i] = (line[i] + (a + b) // 2) & 255
        elif f == 4:
            p = a + b - c
            pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
            line[i] = (line[i] + (a if pa <= pb and pa <= pc else (b if pb <= pc else c))) & 255
        else:
            raise ValueError(f"unknown PNG filter {f}")
    return np.frombuffer(bytes(line), dtype=np.uint8)


def count_color(png: tuple[int, int, int, bytes], rgb: tuple[int, int, int], tol: int = 6) -> int:
    """Pixels within ``tol`` of ``rgb`` on every channel."""
    width, height, ch, px = png
    a = np.frombuffer(px, dtype=np.uint8).reshape(-1, ch)[:, :3].astype(np.int16)
    return int(np.count_nonzero(np.all(np.abs(a - np.array(rgb, dtype=np.int16)) <= tol, axis=1)))


def write_png(path: Path, width: int, height: int, channels: int, px: bytes) -> None:
    stride = width * channels
    raw = b"".join(b"\x00" + px[y * stride : (y + 1) * stride] for y in range(height))

    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF)

    color = 2 if channels == 3 else 6
    Path(path).write_bytes(
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, color, 0, 0, 0))
        + chunk(b"IDAT", zlib.compress(raw))
        + chunk(b"IEND", b"")
    )


def crop(png: tuple[int, int, int, bytes], top: int, bottom: int) -> tuple[int, int, int, bytes]:
    width, height, ch, px = png
    bottom = min(bottom, height)
    return width, bottom - top, ch, px[top * width * ch : bottom * width * ch]
