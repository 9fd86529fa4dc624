#!/usr/bin/env python3
"""Validate striae's path tracer against Mitsuba 3, per pixel block, within Monte Carlo noise.

For each scene file, striae renders it K times with independent seeds, and Mitsuba 3 renders the
same scene (translated by scripts/mitsuba_scene.py: same geometry, camera, lights, IOR, max
depth, box filter, vertical fov) 2K times. Per block of B x B pixels and per channel, Welch's t
compares the mean of striae's K renders with the mean of Mitsuba's first K; the null
distribution of the same statistic is measured, not assumed: Mitsuba's second K renders against
its first K. Agreement means striae-vs-Mitsuba looks like Mitsuba-vs-Mitsuba.

The smooth-glass teapot is checked twice: first with flat normals (its triangles exported by
`striae render --export-meshes` with the vertex normals stripped, loaded as an OBJ by both), then
with smooth normals (striae's built-in teapot; Mitsuba loads the exported OBJ with normals).
The rough GGX materials are checked on the glass teapot with `roughness = 0.2` and the gold
teapot with `roughness = 0.3` (Mitsuba's `roughdielectric` / `roughconductor`, `distribution =
"ggx"`, the same `alpha`). A last scene, `features`, holds what the teapots leave out: a
thin-lens camera, analytic spheres, a spherical light, a sun, an image texture and an
equirectangular environment map turned by a transform.

    cargo build --release
    pip install mitsuba numpy matplotlib
    python3 validation/compare_mitsuba.py [--out validation/out] [--spp 64] [--k 4] [--res 256x192]

Writes, per scene, PNG previews of both means, a figure `NAME-compare.png` (both images, the
t map, histograms of both t statistics) and a table `summary.tsv` whose numbers
docs/validation.md quotes: `numpy.genfromtxt(path, names=True, dtype=None, encoding=None,
delimiter="\t")` reads it.
"""
import argparse
import os
import re
import subprocess
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "scripts"))
import mitsuba_scene  # noqa: E402  (the scene translator)

STRIAE = os.path.join(ROOT, "target", "release", "striae")
SCENES = ["glass-plate", "glass-teapot-flat", "glass-teapot", "metal-teapot", "glass-teapot-rough",
          "metal-teapot-rough", "metal-teapot-rough-flat", "features"]
# Rough (GGX) variants of two scenes, written by `rough_scene`: (source scene, material, alpha).
ROUGH = {"glass-teapot-rough": ("glass-teapot", "glass", 0.2),
         "metal-teapot-rough": ("metal-teapot", "gold", 0.3)}


def flat_teapot_scene(out, src, name):
    """The scene file `src` with its teapot replaced by its exported triangles, no normals, as
    `out/NAME.toml`."""
    mesh_dir = os.path.join(out, "meshes-" + name)
    subprocess.run([STRIAE, "render", src, "--export-meshes", mesh_dir], check=True, stderr=subprocess.DEVNULL)
    text = open(src).read()
    blocks = text.split("[[shapes]]")
    for i, b in enumerate(blocks[1:], start=1):
        if re.search(r'^type\s*=\s*"teapot"', b, re.M):
            obj = os.path.join(mesh_dir, f"shape-{i - 1}.obj")
            flat = os.path.join(out, name + ".obj")
            with open(obj) as f, open(flat, "w") as g:
                for line in f:
                    if line.startswith("vn "):
                        continue
                    if line.startswith("f "):
                        line = "f " + " ".join(v.rsplit("/", 1)[0] if v.count("/") == 2 else v
                                               for v in line.split()[1:]) + "\n"
                    g.write(line)
            lines = [l for l in b.splitlines() if not re.match(r"\s*(subdivisions|transform)\s*=", l)]
            b = "\n".join(lines).replace('type = "teapot"', f'type = "mesh"\npath = "{flat}"') + "\n\n"
            blocks[i] = b
    path = os.path.join(out, name + ".toml")
    with open(path, "w") as f:
        f.write("[[shapes]]".join(blocks))
    return path


def rough_scene(out, name):
    """scenes/SOURCE.toml with `roughness = ALPHA` added to one material (see `ROUGH`)."""
    source, material, alpha = ROUGH[name]
    with open(os.path.join(ROOT, "scenes", source + ".toml")) as f:
        text = f.read()
    header = f"[materials.{material}]\n"
    if header not in text:
        sys.exit(f"{source}.toml has no {header.strip()}")
    path = os.path.join(out, name + ".toml")
    with open(path, "w") as f:
        f.write(text.replace(header, f"{header}roughness = {alpha}\n", 1))
    return path


FEATURES = """# Written by validation/compare_mitsuba.py: what the teapot scenes leave out. A thin-lens
# camera, analytic spheres (smooth glass, rough gold, textured diffuse), a spherical light, a
# sun, an image texture on a sphere, a rectangle, an OBJ quad and a box, and an
# equirectangular environment map turned by a transform, so that the orientation conventions
# of the map and of every shape's uvs are checked too.
[render]
max_depth = 16

[camera]
position = [0.0, 1.6, 5.0]
look_at = [0.0, 0.5, 0.0]
fov = 35.0
aperture_radius = 0.08
focus_distance = 5.0

[materials.glass]
type = "dielectric"
ior = 1.5

[materials.gold]
type = "conductor"
preset = "gold"
roughness = 0.2

[materials.white]
type = "diffuse"
reflectance = { type = "image", path = "features-poster.png" }

[materials.floor]
type = "diffuse"
reflectance = { type = "checkerboard", color0 = [0.7, 0.7, 0.7], color1 = [0.15, 0.15, 0.15], scale = 6.0 }

[materials.poster]
type = "diffuse"
reflectance = { type = "image", path = "features-poster.png" }

[[shapes]]
type = "sphere"
material = "glass"
center = [0.0, 0.5, 0.0]
radius = 0.5

[[shapes]]
type = "sphere"
material = "gold"
center = [-1.2, 0.5, -0.6]
radius = 0.5

[[shapes]]
type = "sphere"
material = "white"
center = [1.2, 0.5, -0.4]
radius = 0.5

[[shapes]]
type = "rectangle"
material = "floor"
transform = [{ scale = 4.0 }, { rotate = { axis = [1, 0, 0], angle = -90 } }]

[[shapes]]                       # a textured wall behind the spheres, facing the camera
type = "rectangle"
material = "poster"
transform = [{ scale = [2.4, 1.2, 1.0] }, { translate = [0.0, 1.2, -2.0] }]

[[shapes]]                       # the same image on an OBJ quad (its own uvs), left of the spheres
type = "mesh"
path = "features-panel.obj"
material = "poster"

[[shapes]]                       # the same image on a turned box (striae's box uvs, exported)
type = "box"
material = "poster"
transform = [{ scale = [0.35, 0.25, 0.3] }, { rotate = { axis = [0, 1, 0], angle = 35 } }, { rotate = { axis = [1, 0, 0], angle = 20 } }, { translate = [0.6, 0.3, 1.2] }]

[[shapes]]                       # a small spherical light
type = "sphere"
center = [1.6, 1.6, 0.8]
radius = 0.15
emission = [6.0, 5.0, 4.0]

[[lights]]
type = "sun"
direction = [0.5, 0.8, 0.4]
irradiance = [2.0, 1.8, 1.5]

[environment]
type = "map"
path = "features-sky.exr"
transform = { rotate = { axis = [0, 1, 0], angle = 40 } }
"""


def features_scene(out):
    """`FEATURES` and its environment map: a sky gradient with a bright warm patch and a green
    one at different azimuths (so a turned or mirrored map shows), 64 x 32, written by Mitsuba."""
    import mitsuba as mi
    w, h = 64, 32
    u = (np.arange(w) + 0.5) / w
    v = np.arange(h) / (h - 1)
    uu, vv = np.meshgrid(u, v)
    sky = np.where(vv[..., None] < 0.5, [0.35, 0.45, 0.7], [0.25, 0.2, 0.15]) * (1.2 - vv[..., None])
    warm = np.exp(-(((uu - 0.3) / 0.05) ** 2 + ((vv - 0.3) / 0.08) ** 2))[..., None] * [12.0, 9.0, 5.0]
    green = np.exp(-(((uu - 0.8) / 0.08) ** 2 + ((vv - 0.45) / 0.1) ** 2))[..., None] * [0.5, 3.0, 0.5]
    mi.Bitmap((sky + warm + green).astype(np.float32)).write(os.path.join(out, "features-sky.exr"))
    # The poster: red rising to the right, green rising downwards, and a white block in the
    # top-left corner, so that a flipped or shifted image shows.
    pw, ph = 48, 24
    x, y = np.meshgrid(np.arange(pw) / (pw - 1), np.arange(ph) / (ph - 1))
    poster = np.stack([0.1 + 0.8 * x, 0.1 + 0.8 * y, np.full_like(x, 0.3)], -1)
    poster[2:8, 3:12] = 1.0
    # A quad standing left of the spheres, turned toward the camera; `vt` (0, 0) at its
    # bottom-left corner, as OBJ files have it.
    with open(os.path.join(out, "features-panel.obj"), "w") as f:
        f.write("v -2.4 0.0 -1.4\nv -1.5 0.0 -0.7\nv -1.5 1.1 -0.7\nv -2.4 1.1 -1.4\n"
                "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3 4/4\n")
    from PIL import Image  # (Pillow comes with matplotlib)
    Image.fromarray((poster * 255).round().astype(np.uint8)).save(os.path.join(out, "features-poster.png"))
    path = os.path.join(out, "features.toml")
    with open(path, "w") as f:
        f.write(FEATURES)
    return path


def scene_path(out, name):
    """The scene file of `name`: one of `scenes/`, or one this script derives from them
    (`NAME-rough`: see `ROUGH`; `NAME-flat`: NAME's teapot with flat normals)."""
    if name.endswith("-flat"):
        return flat_teapot_scene(out, scene_path(out, name[: -len("-flat")]), name)
    if name in ROUGH:
        return rough_scene(out, name)
    if name == "features":
        return features_scene(out)
    return os.path.join(ROOT, "scenes", name + ".toml")


def read_exr(mi, path):
    return np.array(mi.Bitmap(path), dtype=np.float64)[..., :3]


def blocks(img, b):
    h, w, c = img.shape
    h2, w2 = h // b * b, w // b * b
    return img[:h2, :w2].reshape(h2 // b, b, w2 // b, b, c).mean(axis=(1, 3))


def welch_t(a, b):
    """Per block and channel: Welch's t of the difference of means of stacks [K, H, W, C]."""
    va, vb = a.var(0, ddof=1) / a.shape[0], b.var(0, ddof=1) / b.shape[0]
    se = np.sqrt(va + vb)
    with np.errstate(invalid="ignore", divide="ignore"):
        # A relative floor keeps blocks that are noise-free in both (the sky seen directly)
        # from turning float rounding into huge t values.
        se = np.maximum(se, 1e-6 * np.abs(b.mean(0)) + 1e-12)
        return (a.mean(0) - b.mean(0)) / se


def srgb(img):
    x = np.clip(img, 0, None)
    return np.clip(np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055), 0, 1)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=os.path.join(ROOT, "validation", "out"))
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--k", type=int, default=4, help="independent striae renders (Mitsuba gets 2K)")
    ap.add_argument("--res", default="256x192")
    ap.add_argument("--block", type=int, default=4, help="pixel block size of the test")
    ap.add_argument("--variant", default="scalar_rgb")
    ap.add_argument("--only", default=None, help="comma-separated scene names")
    args = ap.parse_args()
    width, height = map(int, args.res.lower().split("x"))
    os.makedirs(args.out, exist_ok=True)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import mitsuba as mi
    mi.set_variant(args.variant)

    rows = []
    for name in SCENES:
        if args.only and name not in args.only.split(","):
            continue
        path = scene_path(args.out, name)
        scene = mi.load_dict(mitsuba_scene.scene_dict(mi, path, STRIAE, (width, height), args.spp, 0))
        S, M, M2, ts, tm = [], [], [], 0.0, 0.0
        for k in range(args.k):
            stem = os.path.join(args.out, f"{name}-striae-{k}")
            t0 = time.time()
            subprocess.run([STRIAE, "render", path, "--res", f"{width}x{height}", "--spp", str(args.spp),
                            "--seed", str(1000 + k), "-o", stem, "-q"], check=True)
            ts += time.time() - t0
            S.append(read_exr(mi, stem + ".exr"))
            t0 = time.time()
            M.append(np.array(mi.render(scene, seed=2000 + k), dtype=np.float64)[..., :3])
            tm += time.time() - t0
            M2.append(np.array(mi.render(scene, seed=3000 + k), dtype=np.float64)[..., :3])
        S, M, M2 = np.stack(S), np.stack(M), np.stack(M2)
        Sb, Mb, M2b = (np.stack([blocks(x, args.block) for x in X]) for X in (S, M, M2))
        t_sm, t_mm = welch_t(Sb, Mb), welch_t(M2b, Mb)
        gs, gm = S.mean(axis=(1, 2)), M.mean(axis=(1, 2))
        rel = (gs.mean(0) - gm.mean(0)) / gm.mean(0)
        se = np.sqrt(gs.var(0, ddof=1) / args.k + gm.var(0, ddof=1) / args.k) / gm.mean(0)
        frac_sm, frac_mm = float(np.mean(np.abs(t_sm) > 3)), float(np.mean(np.abs(t_mm) > 3))
        rmse_sm = float(np.sqrt(np.mean((S.mean(0) - M.mean(0)) ** 2)))
        rmse_mm = float(np.sqrt(np.mean((M2.mean(0) - M.mean(0)) ** 2)))
        rows.append((name, *rel, *se, frac_sm, frac_mm, float(np.mean(t_sm)), float(np.mean(t_mm)), rmse_sm, rmse_mm,
                     ts / args.k, tm / args.k))

        fig, ax = plt.subplots(1, 4, figsize=(17, 3.6))
        ax[0].imshow(srgb(S.mean(0))); ax[0].set_title(f"striae ({args.k} x {args.spp} spp)")
        ax[1].imshow(srgb(M.mean(0))); ax[1].set_title(f"Mitsuba 3 {args.variant} ({args.k} x {args.spp} spp)")
        im = ax[2].imshow(t_sm.mean(-1), cmap="RdBu_r", vmin=-4, vmax=4)
        ax[2].set_title(f"Welch t per {args.block}x{args.block} block (mean of RGB)")
        fig.colorbar(im, ax=ax[2])
        bins = np.linspace(-8, 8, 81)
        ax[3].hist(t_mm.ravel(), bins=bins, alpha=0.6, density=True, label="Mitsuba vs Mitsuba (null)")
        ax[3].hist(t_sm.ravel(), bins=bins, alpha=0.6, density=True, label="striae vs Mitsuba")
        ax[3].set_yscale("log"); ax[3].legend(fontsize=8); ax[3].set_title("t statistics, all blocks and channels")
        for a in ax[:3]:
            a.axis("off")
        fig.suptitle(f"{name}: {width}x{height}; mean relative difference {np.round(rel * 100, 3)} % "
                     f"(+- {np.round(se * 100, 3)} %); |t| > 3: {frac_sm:.4f} vs null {frac_mm:.4f}")
        fig.tight_layout()
        fig.savefig(os.path.join(args.out, f"{name}-compare.png"), dpi=72)
        plt.close(fig)
        print(f"{name}: rel diff {rel} +- {se}; |t|>3 {frac_sm:.4f} (null {frac_mm:.4f}); mean t {np.mean(t_sm):+.3f} "
              f"(null {np.mean(t_mm):+.3f}); rmse {rmse_sm:.5f} (null {rmse_mm:.5f}); s/render striae {ts / args.k:.2f} "
              f"mitsuba {tm / args.k:.2f}", flush=True)

    cols = ["scene", "rel_r", "rel_g", "rel_b", "se_r", "se_g", "se_b", "frac_t3", "frac_t3_null", "mean_t",
            "mean_t_null", "rmse", "rmse_null", "sec_striae", "sec_mitsuba"]
    with open(os.path.join(args.out, "summary.tsv"), "w") as f:
        f.write("\t".join(cols) + "\n")
        for r in rows:
            f.write("\t".join([r[0]] + [f"{x:.6g}" for x in r[1:]]) + "\n")


if __name__ == "__main__":
    main()
