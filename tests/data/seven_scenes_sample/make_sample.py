#!/usr/bin/env python3
"""Writes the tiny hand-made 7-Scenes / 3DMatch sample used by
tests/core/io/seven_scenes_dataset_test.cpp.

Run once from this folder; the files are committed. Plain Python (zlib + struct) so the files do
not depend on the PNG writer under test.

Frames 0, 1 and 3 (2 is missing: a gap in the numbering is allowed), 8x6 pixels.
Depth frame n (16-bit, millimetres): value(u, v) = 1000 + 250 n + 10 v + u, except pixel
(1, 1) = 0 and pixel (2, 1) = 65535 (both "no measurement" in 7-Scenes).
Colour frame n (8-bit RGB PNG): (r, g, b) = (10 u, 20 v, 50 n + 1).
camera-intrinsics.txt: fx = 11, fy = 12, cx = 3.5, cy = 2.5 (tab separated, as tsdf-fusion's).
Poses (T_world_camera), written the way the public datasets write them:
  frame 0: rotation 90 deg about z, t = (1, 2, 3); 7-Scenes style "%.7e" with 3-digit exponents;
  frame 1: rotation 30 deg about z, t = (-0.5, 0.25, 1.5); 7 significant digits, tabs and a
           trailing tab per line (tsdf-fusion style), so the rotation is orthonormal to ~1e-8;
  frame 3: rotation 180 deg about y, t = (0, -1, 0.75); plain numbers, CRLF line ends.
"""
import math
import struct
import zlib

W, H = 8, 6
FRAMES = [0, 1, 3]


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


def depth_value(u, v, n):
    if (u, v) == (1, 1):
        return 0
    if (u, v) == (2, 1):
        return 65535
    return 1000 + 250 * n + 10 * v + u


def windows_e(x):
    """'%.7e' with a 3-digit exponent, as 7-Scenes' pose files (MSVC printf) have it."""
    mantissa, exponent = ("%.7e" % x).split("e")
    return "%se%s%03d" % (mantissa, exponent[0], abs(int(exponent)))


def rz(deg):
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]


def matrix(rotation, t):
    return [rotation[r] + [t[r]] for r in range(3)] + [[0.0, 0.0, 0.0, 1.0]]


def write_text(path, text):
    with open(path, "w", newline="") as f:
        f.write(text)


with open("camera-intrinsics.txt", "w") as f:
    f.write("11\t0\t3.5\n0\t12\t2.5\n0\t0\t1\n")

for n in FRAMES:
    rows = [b"".join(struct.pack(">H", depth_value(u, v, n)) for u in range(W)) for v in range(H)]
    png("frame-%06d.depth.png" % n, 16, 0, rows)
    rows = [bytes(c for u in range(W) for c in (10 * u, 20 * v, 50 * n + 1)) for v in range(H)]
    png("frame-%06d.color.png" % n, 8, 2, rows)

m0 = matrix(rz(90), [1.0, 2.0, 3.0])
write_text("frame-000000.pose.txt",
           "".join("  ".join(windows_e(x) for x in row) + "\n" for row in m0))
m1 = matrix(rz(30), [-0.5, 0.25, 1.5])
write_text("frame-000001.pose.txt",
           "".join("\t".join("%.7g" % x for x in row) + "\t\n" for row in m1))
m3 = matrix([[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]], [0.0, -1.0, 0.75])
write_text("frame-000003.pose.txt",
           "".join(" ".join("%g" % x for x in row) + "\r\n" for row in m3))
