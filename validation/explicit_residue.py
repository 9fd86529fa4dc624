#!/usr/bin/env python3
"""Where an SV-BRDF render and an explicit-groove render of the same scene differ
(docs/fidelity.md, "The SV-BRDF against explicit grooves").

    python3 validation/explicit_residue.py EXPLICIT SV [--sum SUM] [--background B] [--profiles]

EXPLICIT, SV and SUM are path prefixes: `PREFIX_0.exr` and `PREFIX_1.exr` (render seeds 0
and 1: `striae render SCENE --seed S -o PREFIX_S.exr`) are read and averaged. Differences are given as fractions of the scratches' light, the
SV render less the plain surface's radiance `B` (0.02: the metal scenes' environment in the
mirror base), with their noise from the two seeds. The scratched pixels (SV above `B`, grown by
a pixel) are split into connected pieces:

* pieces the image border cuts, where the image holds only part of a scratch (one end, or one
  wall where the border runs along it), against pieces wholly in view;
* with `--profiles`, each whole piece's difference along its length, in ten bins: a difference
  that changes sign from one end to the other is the tapered groove's lean
  (METHOD.md 8.3, `lean = true`);
* with `--sum SUM` (the SV render with `layer_mix = "sum"`; SV with `"union"`), by distance
  from the pixels whose footprint holds scratches of two layers (SUM above SV): crossings.

Needs numpy and striae's Python package (`pip install crates/striae-py`) to read the EXRs.
"""
import argparse
import sys
from collections import deque

import numpy as np

try:
    import striae
except ImportError:
    sys.exit("explicit_residue.py: needs striae's Python package (pip install crates/striae-py)")


def load(prefix):
    """The two seeds' luminance images of a prefix, and their mean."""
    seeds = [striae.read_exr(f"{prefix}_{s}.exr")[..., :3].mean(-1) for s in (0, 1)]
    return (seeds[0] + seeds[1]) / 2, seeds


def grow(mask, pixels=1):
    """`mask` grown by `pixels` (4-neighbourhood steps)."""
    out = mask.copy()
    for _ in range(pixels):
        m = out.copy()
        m[1:] |= out[:-1]
        m[:-1] |= out[1:]
        m[:, 1:] |= out[:, :-1]
        m[:, :-1] |= out[:, 1:]
        out = m
    return out


def pieces(mask):
    """Labels of `mask`'s 8-connected pieces (-1 outside) and their count."""
    label = -np.ones(mask.shape, int)
    count = 0
    h, w = mask.shape
    for i, j in zip(*np.nonzero(mask)):
        if label[i, j] >= 0:
            continue
        label[i, j] = count
        queue = deque([(i, j)])
        while queue:
            a, b = queue.popleft()
            for u in range(max(a - 1, 0), min(a + 2, h)):
                for v in range(max(b - 1, 0), min(b + 2, w)):
                    if mask[u, v] and label[u, v] < 0:
                        label[u, v] = count
                        queue.append((u, v))
        count += 1
    return label, count


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("explicit")
    ap.add_argument("sv")
    ap.add_argument("--sum", help="prefix of the SV render with layer_mix = \"sum\"")
    ap.add_argument("--background", type=float, default=0.02)
    ap.add_argument("--profiles", action="store_true", help="whole pieces' differences along their length")
    args = ap.parse_args()

    x, xs = load(args.explicit)
    sv, ss = load(args.sv)
    if x.shape != sv.shape:
        sys.exit(f"explicit_residue.py: {args.explicit} is {x.shape}, {args.sv} is {sv.shape}")
    diff = x - sv
    var = ((xs[0] - xs[1]) / 2) ** 2 / 2 + ((ss[0] - ss[1]) / 2) ** 2 / 2
    light = sv - args.background
    total = light.sum()
    if not total > 0:
        sys.exit(f"explicit_residue.py: no scratch light above the background {args.background}")

    def share(m):
        """Difference over the scratch light in `m`, with its noise."""
        own = max(light[m].sum(), 1e-12)
        return f"{diff[m].sum() / own:+.4f} (noise {np.sqrt(var[m].sum()) / own:.4f})"

    def part(m):
        """The share of the scratch light in `m`."""
        return f"{light[m].sum() / total:.0%} of the light"

    print(f"means: explicit {x.mean():.5f}, SV {sv.mean():.5f}, explicit / SV {x.mean() / sv.mean():.4f}")
    everything = np.ones_like(light, bool)
    print(f"explicit - SV, of the scratches' light: {share(everything)}")

    label, count = pieces(grow(light > 0.025 * args.background))
    whole = np.zeros_like(everything)
    for k in range(count):
        rows, cols = np.nonzero(label == k)
        if rows.min() > 0 and cols.min() > 0 and rows.max() < light.shape[0] - 1 and cols.max() < light.shape[1] - 1:
            whole |= label == k
    cut = ~whole
    print(f"{count} scratched pieces; cut by the image border ({part(cut)}): {share(cut)}; "
          f"wholly in view: {share(whole)}")

    if args.profiles:
        for k in range(count):
            m = label == k
            if not whole[m].all() or light[m].sum() < 0.02 * total:
                continue
            rows, cols = np.nonzero(m)
            p = np.stack([rows, cols], 1).astype(float)
            wgt = np.maximum(light[m], 1e-12)
            centre = (p * wgt[:, None]).sum(0) / wgt.sum()
            axis = np.linalg.eigh(np.cov((p - centre).T, aweights=wgt))[1][:, 1]
            t = (p - centre) @ axis
            bins = np.minimum(((t - t.min()) / (np.ptp(t) + 1e-9) * 10).astype(int), 9)
            prof = [diff[m][bins == b].sum() / max(light[m][bins == b].sum(), 1e-12) for b in range(10)]
            print(f"  whole piece at rows {rows.min()}-{rows.max()}, columns {cols.min()}-{cols.max()} "
                  f"({part(m)}): {share(m)}; along it: " + " ".join(f"{v:+.3f}" for v in prof))

    if args.sum:
        summed, _ = load(args.sum)
        overlap = (summed - sv) > 0.1 * args.background
        for r in (0, 2, 4, 8):
            near = grow(overlap, r)
            print(f"within {r} px of two layers' scratches ({part(near)}): {share(near)}; "
                  f"farther: {share(~near)}")


if __name__ == "__main__":
    main()
