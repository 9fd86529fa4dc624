#!/usr/bin/env python3
"""Writes crates/striae/scenes/painted-wear.png, the painted scratch map of
scenes/painted.toml (METHOD.md 9.5): a 256 x 256 8-bit grey PNG, each texel the scratched
fraction, holding a few hand-like strokes (curved, thick in the middle and thin at the ends,
their pressure wavering) and a patch of wear brushed one way. Deterministic (its own seed);
needs only the standard library. Run from the repository root:

    python3 scripts/painted_map.py
"""

import math
import random
import struct
import zlib

N = 256
SS = 4  # supersamples per texel side


def png(path, pixels):
    """An 8-bit greyscale PNG of `pixels` (rows of ints 0..255)."""
    raw = b"".join(b"\x00" + bytes(row) for row in pixels)

    def chunk(kind, data):
        c = struct.pack(">I", len(data)) + kind + data
        return c + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n")
        f.write(chunk(b"IHDR", struct.pack(">IIBBBBB", N, N, 8, 0, 0, 0, 0)))
        f.write(chunk(b"IDAT", zlib.compress(raw, 9)))
        f.write(chunk(b"IEND", b""))


def bezier(p0, p1, p2, p3, n=200):
    out = []
    for i in range(n + 1):
        t = i / n
        a, b, c, d = (1 - t) ** 3, 3 * t * (1 - t) ** 2, 3 * t * t * (1 - t), t ** 3
        out.append((a * p0[0] + b * p1[0] + c * p2[0] + d * p3[0],
                    a * p0[1] + b * p1[1] + c * p2[1] + d * p3[1]))
    return out


def main():
    rng = random.Random(95)
    cov = [[0.0] * (N * SS) for _ in range(N * SS)]

    def stamp(x, y, r, value):
        """A disc of radius r (texels) at (x, y) in texels, max-combined."""
        x, y, r = x * SS, y * SS, r * SS
        for j in range(max(0, int(y - r) - 1), min(N * SS, int(y + r) + 2)):
            for i in range(max(0, int(x - r) - 1), min(N * SS, int(x + r) + 2)):
                if (i + 0.5 - x) ** 2 + (j + 0.5 - y) ** 2 <= r * r:
                    row = cov[j]
                    if row[i] < value:
                        row[i] = value

    # Hand strokes: cubic curves, width tapering to the ends, pressure wavering.
    strokes = [
        ((20, 60), (80, 20), (160, 90), (236, 40), 4.0),
        ((30, 200), (90, 150), (150, 230), (220, 170), 3.0),
        ((60, 120), (100, 100), (130, 140), (200, 110), 2.0),
        ((200, 230), (210, 180), (190, 120), (225, 70), 2.5),
    ]
    for p0, p1, p2, p3, w in strokes:
        pts = bezier(p0, p1, p2, p3, 400)
        phase = rng.uniform(0, 6.28)
        for k, (x, y) in enumerate(pts):
            s = k / (len(pts) - 1)
            taper = math.sqrt(max(0.0, 1.0 - (2 * s - 1) ** 2))
            pressure = 0.8 + 0.2 * math.sin(14 * s + phase)
            stamp(x, y, 0.5 * w * taper * pressure + 0.3, 1.0)
    # A brushed patch: many short parallel hairlines at 30 degrees, partly worn (0.6).
    a = math.radians(30)
    for _ in range(60):
        cx, cy = rng.uniform(40, 110), rng.uniform(150, 235)
        length = rng.uniform(8, 24)
        for k in range(40):
            t = (k / 39 - 0.5) * length
            stamp(cx + t * math.cos(a), cy + t * math.sin(a), 0.6, 0.6)
    pixels = []
    for y in range(N):
        row = []
        for x in range(N):
            s = 0.0
            for j in range(SS):
                r = cov[y * SS + j]
                s += sum(r[x * SS:(x + 1) * SS])
            row.append(int(round(255 * s / (SS * SS))))
        pixels.append(row)
    png("crates/striae/scenes/painted-wear.png", pixels)


if __name__ == "__main__":
    main()
