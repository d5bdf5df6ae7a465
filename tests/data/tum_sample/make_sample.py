#!/usr/bin/env python3
"""Writes the tiny hand-made TUM RGB-D sample used by tests/core/io/tum_dataset_test.cpp.

Run once from this folder; the PNGs are committed. Plain Python (zlib + struct) so the files do
not depend on the PNG writer under test.

Depth image k (8x6, 16-bit): value(u, v) = 5000 + 250 k + 10 v + u, except pixel (1, 1) = 0
("no measurement"). Colour image k (8x6, 8-bit RGB): (r, g, b) = (10 u, 20 v, 50 k + 1).
"""
import struct
import zlib

W, H = 8, 6
DEPTH_TIMES = ["100.000000", "100.033000", "100.200000", "100.400000"]
RGB_TIMES = ["100.008000", "100.208000", "100.408000"]


def chunk(kind, data):
    body = kind + data
    return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body) & 0xFFFFFFFF)


def png(path, bit_depth, colour_type, rows):
    raw = b"".join(b"\x00" + row for row in rows)
    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n")
        f.write(chunk(b"IHDR", struct.pack(">IIBBBBB", W, H, bit_depth, colour_type, 0, 0, 0)))
        f.write(chunk(b"IDAT", zlib.compress(raw)))
        f.write(chunk(b"IEND", b""))


def depth_value(u, v, k):
    return 0 if (u, v) == (1, 1) else 5000 + 250 * k + 10 * v + u


for k, t in enumerate(DEPTH_TIMES):
    rows = [b"".join(struct.pack(">H", depth_value(u, v, k)) for u in range(W)) for v in range(H)]
    png(f"depth/{t}.png", 16, 0, rows)

for k, t in enumerate(RGB_TIMES):
    rows = [bytes(c for u in range(W) for c in (10 * u, 20 * v, 50 * k + 1)) for v in range(H)]
    png(f"rgb/{t}.png", 8, 2, rows)
