#!/usr/bin/env python3
"""Measure a halo image (METHOD.md 8.4): the lit pieces of the scratches against the radial
direction from the halo's centre.

Usage: halo_measure.py IMAGE.png [--threshold T] [--centre X Y]

Reads an 8-bit RGB(A) PNG (pure Python: zlib and the PNG filters), marks pixels brighter than
T (0-255, luminance), splits them into 8-connected pieces, and takes the largest piece as the
light's mirror image (or its image through the pane): the halo's centre is its centroid unless
--centre is given. For every other piece of at least 3 pixels it fits the principal axis
(second moments) and reports the angle between that axis and the radial direction from the
centre to the piece's centroid: 90 degrees is a piece running around the centre (a halo arc),
0 one pointing at it (a spoke). Prints the count, the median and the mean of the angle, the
share of pieces above 60 degrees, and the same statistics weighted by piece size; and how evenly
the lit pixels spread around the centre (the share held by the 9 fullest of 36 sectors of polar
angle: 0.25 when even, as halos are; spokes crowd a few sectors).

The centre as docs/fidelity.md gives it (pixel coordinates, pixel centres at +0.5): the light's
mirror image for scenes/halo-reflection.toml, `--centre 216.7 173.5`; the light seen through the
pane for scenes/halo-transmission.toml, `--centre 166.4 209.4` (there the brightest arcs touch
the light's image, so the largest piece is not the light alone).
"""
import struct
import sys
import zlib


def read_png(path):
    data = open(path, "rb").read()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", "not a PNG"
    pos, idat, w = 8, b"", None
    while pos < len(data):
        n, kind = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + n]
        if kind == b"IHDR":
            w, h, depth, colour, _, _, interlace = struct.unpack(">IIBBBBB", body)
            assert depth == 8 and colour in (2, 6) and interlace == 0, "8-bit RGB(A) only"
            bpp = 3 if colour == 2 else 4
        elif kind == b"IDAT":
            idat += body
        pos += 12 + n
    raw = zlib.decompress(idat)
    stride = w * bpp
    rows, prev = [], bytearray(stride)
    for y in range(h):
        f = raw[y * (stride + 1)]
        line = bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
        for i in range(stride):
            a = line[i - bpp] if i >= bpp else 0
            b = prev[i]
            c = prev[i - bpp] if i >= bpp else 0
            if f == 1:
                line[i] = (line[i] + a) & 255
            elif f == 2:
                line[i] = (line[i] + b) & 255
            elif f == 3:
                line[i] = (line[i] + (a + b) // 2) & 255
            elif f == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                pred = a if pa <= pb and pa <= pc else (b if pb <= pc else c)
                line[i] = (line[i] + pred) & 255
        rows.append([0.2126 * line[x * bpp] + 0.7152 * line[x * bpp + 1] + 0.0722 * line[x * bpp + 2]
                     for x in range(w)])
        prev = line
    return w, h, rows


def pieces(w, h, rows, t):
    seen = [[False] * w for _ in range(h)]
    out = []
    for y in range(h):
        for x in range(w):
            if seen[y][x] or rows[y][x] < t:
                continue
            stack, comp = [(x, y)], []
            seen[y][x] = True
            while stack:
                px, py = stack.pop()
                comp.append((px, py))
                for dy in (-1, 0, 1):
                    for dx in (-1, 0, 1):
                        qx, qy = px + dx, py + dy
                        if 0 <= qx < w and 0 <= qy < h and not seen[qy][qx] and rows[qy][qx] >= t:
                            seen[qy][qx] = True
                            stack.append((qx, qy))
            out.append(comp)
    return out


def main():
    import math
    args = sys.argv[1:]
    path, t, centre = args[0], 60.0, None
    if "--threshold" in args:
        t = float(args[args.index("--threshold") + 1])
    if "--centre" in args:
        i = args.index("--centre")
        centre = (float(args[i + 1]), float(args[i + 2]))
    w, h, rows = read_png(path)
    comps = sorted(pieces(w, h, rows, t), key=len, reverse=True)
    if not comps:
        print("no lit pixels above the threshold")
        return
    if centre is None:
        big = comps[0]
        centre = (sum(p[0] for p in big) / len(big), sum(p[1] for p in big) / len(big))
        comps = comps[1:]
    angles = []
    for c in comps:
        if len(c) < 3:
            continue
        n = len(c)
        mx, my = sum(p[0] for p in c) / n, sum(p[1] for p in c) / n
        sxx = sum((p[0] - mx) ** 2 for p in c) / n
        syy = sum((p[1] - my) ** 2 for p in c) / n
        sxy = sum((p[0] - mx) * (p[1] - my) for p in c) / n
        # Elongated pieces only: a round blob has no direction.
        tr, det = sxx + syy, sxx * syy - sxy * sxy
        disc = math.sqrt(max(tr * tr / 4 - det, 0.0))
        l1, l2 = tr / 2 + disc, tr / 2 - disc
        if l1 <= 0 or l2 / l1 > 0.25:
            continue
        ax = 0.5 * math.atan2(2 * sxy, sxx - syy)
        rx, ry = mx - centre[0], my - centre[1]
        if math.hypot(rx, ry) < 3:
            continue
        rad = math.atan2(ry, rx)
        d = abs((ax - rad + math.pi / 2) % math.pi - math.pi / 2)
        angles.append((math.degrees(d), n))
    # Where the lit pixels lie around the centre: 36 sectors of polar angle. Halos fill them
    # evenly (the 9 fullest hold about a quarter); spokes crowd a few.
    sectors = [0] * 36
    for c in comps:
        for (px, py) in c:
            a = math.atan2(py - centre[1], px - centre[0])
            sectors[int((a + math.pi) / (2 * math.pi) * 36) % 36] += 1
    total = sum(sectors)
    if total:
        top = sum(sorted(sectors, reverse=True)[:9]) / total
        print(f"{path}: lit pixels in the 9 fullest of 36 sectors around the centre: {top:.2f} (even: 0.25)")
    if not angles:
        print("no elongated pieces")
        return
    a = sorted(x[0] for x in angles)
    wsum = sum(x[1] for x in angles)
    print(f"{path}: centre ({centre[0]:.1f}, {centre[1]:.1f}), {len(angles)} elongated pieces")
    print(f"  angle to the radial direction: median {a[len(a) // 2]:.1f} deg, mean {sum(a) / len(a):.1f} deg, "
          f"share above 60 deg {sum(1 for x in a if x > 60) / len(a):.2f}")
    print(f"  weighted by pixels: mean {sum(x[0] * x[1] for x in angles) / wsum:.1f} deg, "
          f"share above 60 deg {sum(x[1] for x in angles if x[0] > 60) / wsum:.2f}")


if __name__ == "__main__":
    main()
