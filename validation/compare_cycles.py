"""striae against Blender's Cycles on one glTF file that Blender itself wrote (docs/blender.md).

    cargo build --release
    pip install ./ numpy matplotlib          # the striae package reads the EXRs
    python3 validation/compare_cycles.py --spp 1024 --k 4 --out validation/out-cycles

`crates/striae/scenes/blender/blender-scene.glb` and its Cycles reference
`blender-scene-cycles.exr` (CPU path tracing, 4096 spp, the settings listed in
`scripts/blender/make_scene.py`) are committed; this script renders the .glb with striae K times
(independent seeds) at the reference's resolution and compares:

* the whole image's mean per channel, striae over Cycles, with its standard error from the
  spread between striae's seeds (the one exposure factor between the renderers: 1 where both
  define light alike);
* means over blocks of B x B pixels: the relative difference per block where Cycles' block is
  lit (luminance above 2 % of the brightest block), its median and 90th percentile, against the
  same figures between striae's own seeds (Monte Carlo noise alone);
* the correlation of the blocks' log luminance (structure);
* named regions (floor in the light, copper cube, glass sphere, the sphere's shadow).

It writes `summary.tsv` (numpy.genfromtxt(path, names=True, dtype=None, encoding=None,
delimiter="\\t") reads it) and `cycles-compare.png` (Cycles, striae, per-block ratio).
"""

import argparse
import os
import subprocess
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENE_DIR = os.path.join(ROOT, "crates", "striae", "scenes", "blender")
LUMA = np.array([0.2126, 0.7152, 0.0722])

# Regions in pixels of the 160 x 120 reference, (x0, y0, x1, y1), exclusive ends; checked on
# `cycles-compare.png`, which outlines them.
REGIONS = {
    "floor lit": (100, 95, 150, 112),
    "floor far": (0, 42, 30, 52),
    "copper cube": (94, 44, 120, 70),
    "glass sphere": (38, 38, 66, 64),
    "caustic": (44, 72, 62, 80),
    "sphere shadow": (4, 60, 28, 72),
}


def block_means(img, b):
    h, w = img.shape[0] // b * b, img.shape[1] // b * b
    return img[:h, :w].reshape(h // b, b, w // b, b, 3).mean(axis=(1, 3))


def lit_rel_diff(a, ref, floor):
    """|a / ref - 1| of luminance over blocks whose reference luminance exceeds `floor`."""
    la, lr = a @ LUMA, ref @ LUMA
    lit = lr > floor
    return np.abs(la[lit] / lr[lit] - 1.0), lit


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--glb", default=os.path.join(SCENE_DIR, "blender-scene.glb"))
    p.add_argument("--cycles", default=os.path.join(SCENE_DIR, "blender-scene-cycles.exr"))
    p.add_argument("--striae", default=os.path.join(ROOT, "target", "release", "striae"))
    p.add_argument("--spp", type=int, default=1024)
    p.add_argument("--k", type=int, default=4, help="striae renders with independent seeds")
    p.add_argument("--block", type=int, default=8)
    p.add_argument("--out", default=os.path.join(ROOT, "validation", "out-cycles"))
    a = p.parse_args()

    import striae

    os.makedirs(a.out, exist_ok=True)
    cycles = striae.read_exr(a.cycles).astype(np.float64)
    h, w = cycles.shape[:2]
    renders = []
    for seed in range(a.k):
        out = os.path.join(a.out, f"striae-{seed}.exr")
        cmd = [a.striae, "render", a.glb, "--spp", str(a.spp), "--res", f"{w}x{h}",
               "--seed", str(seed + 1), "-o", out]
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
        renders.append(striae.read_exr(out).astype(np.float64))
    s = np.mean(renders, axis=0)

    # The whole image, per channel: striae / Cycles, with the standard error between seeds.
    means = np.array([r.reshape(-1, 3).mean(axis=0) for r in renders])
    ratio = means.mean(axis=0) / cycles.reshape(-1, 3).mean(axis=0)
    ratio_se = means.std(axis=0, ddof=1) / np.sqrt(a.k) / cycles.reshape(-1, 3).mean(axis=0)

    bc, bs = block_means(cycles, a.block), block_means(s, a.block)
    floor = 0.02 * (bc @ LUMA).max()
    rel, lit = lit_rel_diff(bs, bc, floor)
    # Noise alone: the first half of striae's seeds against the second half, each half's mean
    # having the noise of K/2 renders (so sqrt(2) x the noise of the K-render mean above).
    half = a.k // 2
    noise, _ = lit_rel_diff(block_means(np.mean(renders[:half], axis=0), a.block),
                            block_means(np.mean(renders[half:], axis=0), a.block), floor)
    lc, ls = np.log(bc @ LUMA + 1e-6), np.log(bs @ LUMA + 1e-6)
    corr = np.corrcoef(lc[lit], ls[lit])[0, 1]

    rows = [("whole image", f"{ratio[0]:.4f} {ratio[1]:.4f} {ratio[2]:.4f}",
             f"{ratio_se.max():.4f}")]
    for name, (x0, y0, x1, y1) in REGIONS.items():
        rc = cycles[y0:y1, x0:x1].reshape(-1, 3).mean(axis=0)
        rs = np.array([r[y0:y1, x0:x1].reshape(-1, 3).mean(axis=0) for r in renders])
        q = rs.mean(axis=0) / rc
        se = rs.std(axis=0, ddof=1) / np.sqrt(a.k) / rc
        rows.append((name, f"{q[0]:.4f} {q[1]:.4f} {q[2]:.4f}", f"{se.max():.4f}"))

    with open(os.path.join(a.out, "summary.tsv"), "w") as f:
        f.write("measure\tvalue\tnoise\n")
        for name, q, se in rows:
            f.write(f"ratio {name} (r g b)\t{q}\t{se}\n")
        f.write(f"lit blocks\t{int(lit.sum())}\t{lit.size}\n")
        f.write(f"median |block diff|\t{np.median(rel):.4f}\t{np.median(noise) / np.sqrt(2):.4f}\n")
        f.write(f"p90 |block diff|\t{np.percentile(rel, 90):.4f}\t"
                f"{np.percentile(noise, 90) / np.sqrt(2):.4f}\n")
        f.write(f"log-luminance correlation\t{corr:.4f}\t\n")
    print(open(os.path.join(a.out, "summary.tsv")).read(), end="")

    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        from matplotlib.patches import Rectangle
    except ImportError:
        print("matplotlib not installed: no figure", file=sys.stderr)
        return

    def tone(img):
        return np.clip(img, 0, 1) ** (1 / 2.2)

    fig, ax = plt.subplots(1, 3, figsize=(13, 3.6))
    ax[0].imshow(tone(cycles))
    ax[0].set_title("Cycles (4096 spp)")
    ax[1].imshow(tone(s))
    ax[1].set_title(f"striae ({a.k} x {a.spp} spp)")
    for name, (x0, y0, x1, y1) in REGIONS.items():
        for axis in ax[:2]:
            axis.add_patch(Rectangle((x0 - 0.5, y0 - 0.5), x1 - x0, y1 - y0, fill=False,
                                     edgecolor="yellow", linewidth=0.8))
    lr = np.full(lit.shape, np.nan)
    lr[lit] = np.log2(np.maximum(bs @ LUMA, 1e-9)[lit] / (bc @ LUMA)[lit])
    im = ax[2].imshow(lr, cmap="RdBu_r", vmin=-0.5, vmax=0.5)
    ax[2].set_title(f"log2 striae / Cycles, {a.block} x {a.block} blocks")
    fig.colorbar(im, ax=ax[2], fraction=0.035)
    for axis in ax:
        axis.set_xticks([])
        axis.set_yticks([])
    fig.tight_layout()
    fig.savefig(os.path.join(a.out, "cycles-compare.png"), dpi=110)


if __name__ == "__main__":
    main()
