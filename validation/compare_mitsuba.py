#!/usr/bin/env python3
"""Validate striae's path tracer against Mitsuba 3 on smooth-glass scenes.

Each scene is described once, below, in a small neutral form; the script writes it as a striae
TOML file and as a Mitsuba 3 scene dictionary (same geometry, camera, lights, IOR, max depth,
box filter, vertical fov), renders both with K independent seeds each, and compares them per
pixel block with Welch's t statistic. The null distribution of that statistic is measured, not
assumed: the same test between two disjoint halves of Mitsuba's own seeds. Agreement means the
striae-vs-Mitsuba statistics look like the Mitsuba-vs-Mitsuba ones.

Usage (from the repository root, after `cargo build --release`):

    pip install mitsuba numpy matplotlib
    python3 validation/compare_mitsuba.py --out validation/out [--spp 64] [--k 6] [--res 256x192]

Writes per scene: both renders (EXR as .npy means, PNG previews), a t-statistic map, and a
summary table `summary.tsv` (numpy.loadtxt-readable) used in docs/validation.md.
"""
import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
STRIAE = os.path.join(ROOT, "target", "release", "striae")

# ----------------------------------------------------------------------------------------
# Scenes in a neutral form. Transforms are lists of operations applied in order (striae's
# convention); the Mitsuba side composes them in reverse matrix order.
# ----------------------------------------------------------------------------------------

FLOOR = {"shape": "rectangle", "material": ("diffuse", 0.5),
         "transform": [("scale", 6.0), ("rotate", [1, 0, 0], -90.0)]}
LIGHT = {"shape": "rectangle", "emission": [12.0, 11.0, 10.0],
         "transform": [("scale", 0.75), ("rotate", [1, 0, 0], 90.0), ("translate", [-1.5, 4.0, 1.5])]}
ENV = [0.25, 0.3, 0.4]


def scenes(teapot_obj_smooth, teapot_obj_flat):
    plate = {"shape": "box", "material": ("dielectric", 1.5),
             "transform": [("scale", [1.5, 1.0, 0.02]), ("rotate", [0, 1, 0], 25.0), ("translate", [0.0, 1.0, 0.0])]}
    teapot = lambda path: {"shape": "obj", "path": path, "material": ("dielectric", 1.5),
                           "transform": [("scale", 0.5), ("rotate", [0, 1, 0], -30.0)]}
    return {
        "glass-plate": {"camera": {"position": [0.0, 1.6, 5.5], "look_at": [0.0, 1.0, 0.0], "up": [0, 1, 0], "fov": 30.0},
                        "shapes": [plate, FLOOR, LIGHT], "env": ENV},
        "glass-teapot-flat": {"camera": {"position": [0.0, 2.6, 6.0], "look_at": [0.0, 0.7, 0.0], "up": [0, 1, 0], "fov": 30.0},
                              "shapes": [teapot(teapot_obj_flat), FLOOR, LIGHT], "env": ENV},
        "glass-teapot-smooth": {"camera": {"position": [0.0, 2.6, 6.0], "look_at": [0.0, 0.7, 0.0], "up": [0, 1, 0], "fov": 30.0},
                                "shapes": [teapot(teapot_obj_smooth), FLOOR, LIGHT], "env": ENV},
    }


# ---------------------------------- striae side -----------------------------------------

def toml_value(v):
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    if isinstance(v, str):
        return json.dumps(v)
    return repr(float(v)) if isinstance(v, float) else str(v)


def toml_transform(ops):
    out = []
    for op in ops:
        if op[0] == "scale":
            out.append("{ scale = %s }" % toml_value(op[1]))
        elif op[0] == "rotate":
            out.append("{ rotate = { axis = %s, angle = %s } }" % (toml_value(op[1]), toml_value(op[2])))
        elif op[0] == "translate":
            out.append("{ translate = %s }" % toml_value(op[1]))
    return "[" + ", ".join(out) + "]"


def striae_toml(sc, width, height, spp, max_depth, seed):
    lines = ["[render]", f"width = {width}", f"height = {height}", f"spp = {spp}",
             f"max_depth = {max_depth}", f"seed = {seed}", "", "[camera]"]
    cam = sc["camera"]
    lines += [f"position = {toml_value(cam['position'])}", f"look_at = {toml_value(cam['look_at'])}",
              f"up = {toml_value(cam['up'])}", f"fov = {cam['fov']}", ""]
    mats = {}
    for i, s in enumerate(sc["shapes"]):
        if "material" in s:
            mats[f"m{i}"] = s["material"]
    for name, (kind, val) in mats.items():
        lines.append(f"[materials.{name}]")
        if kind == "diffuse":
            lines += ['type = "diffuse"', f"reflectance = {toml_value([float(val)] * 3)}"]
        elif kind == "dielectric":
            lines += ['type = "dielectric"', f"ior = {val}"]
        lines.append("")
    for i, s in enumerate(sc["shapes"]):
        lines.append("[[shapes]]")
        kind = {"obj": "mesh"}.get(s["shape"], s["shape"])
        lines.append(f'type = "{kind}"')
        if kind == "mesh":
            lines.append(f"path = {json.dumps(s['path'])}")
        if "material" in s:
            lines.append(f'material = "m{i}"')
        if "emission" in s:
            lines.append(f"emission = {toml_value(s['emission'])}")
        lines.append(f"transform = {toml_transform(s['transform'])}")
        lines.append("")
    lines += ["[environment]", 'type = "constant"', f"radiance = {toml_value(sc['env'])}", ""]
    return "\n".join(lines)


def read_exr(path):
    import mitsuba as mi
    return np.array(mi.Bitmap(path), dtype=np.float64)[..., :3]


def render_striae(sc, out, tag, width, height, spp, max_depth, seed):
    path = os.path.join(out, f"{tag}.toml")
    with open(path, "w") as f:
        f.write(striae_toml(sc, width, height, spp, max_depth, seed))
    stem = os.path.join(out, f"{tag}-striae-{seed}")
    t = time.time()
    subprocess.run([STRIAE, "render", path, "-o", stem, "-q"], check=True)
    return read_exr(stem + ".exr"), time.time() - t


# ---------------------------------- Mitsuba side ----------------------------------------

def mi_transform(mi, ops):
    T = mi.ScalarTransform4f
    m = T()
    for op in ops:  # the first op acts first: left-multiply each new one
        if op[0] == "scale":
            s = op[1] if isinstance(op[1], (list, tuple)) else [op[1]] * 3
            m = T().scale(s) @ m
        elif op[0] == "rotate":
            m = T().rotate(op[1], op[2]) @ m
        elif op[0] == "translate":
            m = T().translate(op[1]) @ m
    return m


def mitsuba_dict(mi, sc, width, height, spp, max_depth, seed):
    cam = sc["camera"]
    d = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": max_depth, "rr_depth": 5},
        "sensor": {
            "type": "perspective", "fov": cam["fov"], "fov_axis": "y",
            "to_world": mi.ScalarTransform4f().look_at(origin=cam["position"], target=cam["look_at"], up=cam["up"]),
            "film": {"type": "hdrfilm", "width": width, "height": height, "rfilter": {"type": "box"}, "pixel_format": "rgb"},
            "sampler": {"type": "independent", "sample_count": spp, "seed": seed},
        },
        "env": {"type": "constant", "radiance": {"type": "rgb", "value": sc["env"]}},
    }
    for i, s in enumerate(sc["shapes"]):
        kind = {"box": "cube"}.get(s["shape"], s["shape"])
        shape = {"type": kind, "to_world": mi_transform(mi, s["transform"])}
        if kind == "obj":
            shape["filename"] = s["path"]
        if "material" in s:
            mk, val = s["material"]
            if mk == "diffuse":
                shape["bsdf"] = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [val] * 3}}
            else:
                shape["bsdf"] = {"type": "dielectric", "int_ior": val, "ext_ior": 1.0}
        else:
            # An emitter without a material reflects nothing (as in striae).
            shape["bsdf"] = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.0, 0.0, 0.0]}}
        if "emission" in s:
            shape["emitter"] = {"type": "area", "radiance": {"type": "rgb", "value": s["emission"]}}
        d[f"shape{i}"] = shape
    return d


def render_mitsuba(mi, sc, width, height, spp, max_depth, seed):
    scene = mi.load_dict(mitsuba_dict(mi, sc, width, height, spp, max_depth, seed))
    t = time.time()
    img = np.array(mi.render(scene, spp=spp, seed=seed), dtype=np.float64)[..., :3]
    return img, time.time() - t


# ---------------------------------- statistics ------------------------------------------

def blocks(img, b):
    h, w, c = img.shape
    h2, w2 = h // b * b, w // b * b
    return img[:h2, :w2].reshape(h2 // b, b, w2 // b, b, c).mean(axis=(1, 3))


def welch_t(a, b):
    """Per block and channel: t of the difference of means of two stacks [K, H, W, C]."""
    ma, mb = a.mean(0), b.mean(0)
    va, vb = a.var(0, ddof=1) / a.shape[0], b.var(0, ddof=1) / b.shape[0]
    se = np.sqrt(va + vb)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.where(se > 0, (ma - mb) / se, 0.0)
    return t


def srgb_png(img, path):
    import matplotlib.pyplot as plt
    x = np.clip(img, 0, None)
    x = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    plt.imsave(path, np.clip(x, 0, 1))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=os.path.join(ROOT, "validation", "out"))
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--k", type=int, default=6, help="independent striae renders (Mitsuba gets 2K)")
    ap.add_argument("--res", default="256x192")
    ap.add_argument("--max-depth", type=int, default=16)
    ap.add_argument("--block", type=int, default=4, help="pixel block size for the test")
    ap.add_argument("--variant", default="scalar_rgb")
    ap.add_argument("--only", default=None, help="comma-separated scene names")
    args = ap.parse_args()
    width, height = map(int, args.res.lower().split("x"))
    os.makedirs(args.out, exist_ok=True)
    import mitsuba as mi
    mi.set_variant(args.variant)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    smooth = os.path.join(args.out, "teapot-smooth.obj")
    flat = os.path.join(args.out, "teapot-flat.obj")
    subprocess.run([STRIAE, "mesh", "teapot", "--subdivisions", "8", "-o", smooth], check=True)
    subprocess.run([STRIAE, "mesh", "teapot", "--subdivisions", "8", "--flat", "-o", flat], check=True)

    rows = []
    for name, sc in scenes(smooth, flat).items():
        if args.only and name not in args.only.split(","):
            continue
        # K striae renders; 2K Mitsuba renders: the first K are the reference, the second K
        # measure the null distribution (Mitsuba against itself, same K and spp).
        S, M, M2, ts, tm = [], [], [], 0.0, 0.0
        for k in range(args.k):
            img, dt = render_striae(sc, args.out, name, width, height, args.spp, args.max_depth, 1000 + k)
            S.append(img); ts += dt
            img, dt = render_mitsuba(mi, sc, width, height, args.spp, args.max_depth, 2000 + k)
            M.append(img); tm += dt
            img, _ = render_mitsuba(mi, sc, width, height, args.spp, args.max_depth, 3000 + k)
            M2.append(img)
        S, M, M2 = np.stack(S), np.stack(M), np.stack(M2)
        np.save(os.path.join(args.out, f"{name}-striae.npy"), S.mean(0))
        np.save(os.path.join(args.out, f"{name}-mitsuba.npy"), M.mean(0))
        srgb_png(S.mean(0), os.path.join(args.out, f"{name}-striae.png"))
        srgb_png(M.mean(0), os.path.join(args.out, f"{name}-mitsuba.png"))
        Sb = np.stack([blocks(x, args.block) for x in S])
        Mb = np.stack([blocks(x, args.block) for x in M])
        M2b = np.stack([blocks(x, args.block) for x in M2])
        t_sm = welch_t(Sb, Mb)
        t_mm = welch_t(M2b, Mb)
        # Global means per channel with standard errors across seeds.
        gs, gm = S.mean(axis=(1, 2)), M.mean(axis=(1, 2))
        rel = (gs.mean(0) - gm.mean(0)) / gm.mean(0)
        se = np.sqrt(gs.var(0, ddof=1) / args.k + gm.var(0, ddof=1) / args.k) / gm.mean(0)
        # Fraction of block-channels beyond |t| > 3 in each comparison.
        frac_sm = float(np.mean(np.abs(t_sm) > 3))
        frac_mm = float(np.mean(np.abs(t_mm) > 3))
        rmse_sm = float(np.sqrt(np.mean((S.mean(0) - M.mean(0)) ** 2)))
        rmse_mm = float(np.sqrt(np.mean((M2.mean(0) - M.mean(0)) ** 2)))
        rows.append((name, *rel, *se, frac_sm, frac_mm, rmse_sm, rmse_mm, ts / args.k, tm / args.k))
        fig, ax = plt.subplots(1, 4, figsize=(16, 3.4))
        ax[0].imshow(plt.imread(os.path.join(args.out, f"{name}-striae.png"))); ax[0].set_title("striae")
        ax[1].imshow(plt.imread(os.path.join(args.out, f"{name}-mitsuba.png"))); ax[1].set_title("Mitsuba 3 " + args.variant)
        im = ax[2].imshow(t_sm.mean(-1), cmap="RdBu_r", vmin=-4, vmax=4); ax[2].set_title("t: striae vs Mitsuba (block mean)")
        fig.colorbar(im, ax=ax[2])
        bins = np.linspace(-6, 6, 61)
        ax[3].hist(t_mm.ravel(), bins=bins, alpha=0.6, density=True, label="Mitsuba vs Mitsuba")
        ax[3].hist(t_sm.ravel(), bins=bins, alpha=0.6, density=True, label="striae vs Mitsuba")
        ax[3].set_yscale("log"); ax[3].legend(fontsize=8); ax[3].set_title("t statistics")
        for a in ax[:3]:
            a.axis("off")
        fig.suptitle(f"{name}: {width}x{height}, {args.spp} spp x {args.k} seeds each")
        fig.tight_layout()
        fig.savefig(os.path.join(args.out, f"{name}-compare.png"), dpi=80)
        plt.close(fig)
        print(f"{name}: mean rel diff {rel} +- {se}; |t|>3: striae-mitsuba {frac_sm:.4f}, mitsuba-mitsuba {frac_mm:.4f}; "
              f"rmse {rmse_sm:.5f} vs noise {rmse_mm:.5f}; time/render striae {ts/args.k:.2f}s mitsuba {tm/args.k:.2f}s", flush=True)

    header = "scene\trel_r\trel_g\trel_b\tse_r\tse_g\tse_b\tfrac_t3_striae_mitsuba\tfrac_t3_mitsuba_mitsuba\trmse_striae_mitsuba\trmse_noise\tsec_striae\tsec_mitsuba"
    with open(os.path.join(args.out, "summary.tsv"), "w") as f:
        f.write("# " + header + "\n")
        for r in rows:
            f.write("\t".join([r[0]] + [f"{x:.6g}" for x in r[1:]]) + "\n")


if __name__ == "__main__":
    main()
