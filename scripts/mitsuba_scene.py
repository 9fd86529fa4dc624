#!/usr/bin/env python3
"""Describe a striae scene file (TOML, docs/scenes.md) to Mitsuba 3 and render it there.

    python3 scripts/mitsuba_scene.py scenes/glass-plate.toml -o /tmp/mi.exr --spp 64 \
        [--res 128x96] [--seed 0] [--variant scalar_rgb] [--striae target/release/striae]

The conventions that differ between the two renderers are translated here, once:
* camera: striae's `fov` is vertical -> Mitsuba `fov_axis = "y"`; box pixel filter;
* dielectric: striae's `ext_ior` defaults to 1.0 (Mitsuba: 1.000277) -> both set explicitly;
* opaque materials: striae's reflect on both sides, Mitsuba's on the front only -> `twosided`;
* emitters: a shape with `emission` and no material reflects nothing -> black diffuse BSDF;
* sun: striae's `direction` points toward the sun, Mitsuba's `directional` along the light;
* depth: striae's `max_depth = 0` (unlimited) -> Mitsuba's -1; `rr_depth` carried over;
* rectangles and spheres use Mitsuba's own shapes (the same parametrisations, uv included)
  with the transform computed here; teapots, boxes and OBJ meshes are exported by `striae
  render --export-meshes` in world space and loaded as OBJ (identical triangles, normals and
  uvs: striae's box lays out its faces' uvs differently from Mitsuba's `cube`).
Image textures become Mitsuba `bitmap`s with striae's filtering; both renderers flip an OBJ
file's `vt` the same way (`1 - v`), so an image on an OBJ mesh comes out the same way up.
"""

import argparse
import math
import os
import subprocess
import sys
import tempfile
import tomllib

import numpy as np

# striae's conductor presets (crates/striae/src/material.rs, CONDUCTOR_PRESETS).
PRESETS = {
    ("none", "mirror"): ([0.0, 0.0, 0.0], [1.0, 1.0, 1.0]),
    ("au", "gold"): ([0.14311896, 0.37495704, 1.4424786], [3.9831604, 2.3857207, 1.6032153]),
    ("ag", "silver"): ([0.15526465, 0.1167233, 0.1383807], [4.8283433, 3.1222458, 2.1469504]),
    ("cu", "copper"): ([0.2004377, 0.9240334, 1.102212], [3.9129486, 2.4528477, 2.142188]),
    ("al", "aluminium", "aluminum"): ([1.65746, 0.88036896, 0.5212287], [9.223869, 6.2695234, 4.837001]),
    ("cr", "chromium", "chrome"): ([4.369683, 2.9167025, 1.6547005], [5.206434, 4.2313647, 3.7549467]),
    ("fe", "iron", "steel"): ([2.9114, 2.9497, 2.5845], [3.0893, 2.9318, 2.7670]),
}


def rgb(v):
    return [float(v)] * 3 if isinstance(v, (int, float)) else [float(x) for x in v]


def rotation(axis, degrees):
    a = np.asarray(axis, float)
    a = a / np.linalg.norm(a)
    t = math.radians(degrees)
    c, s = math.cos(t), math.sin(t)
    x, y, z = a
    r = np.array([
        [c + x * x * (1 - c), x * y * (1 - c) - z * s, x * z * (1 - c) + y * s],
        [y * x * (1 - c) + z * s, c + y * y * (1 - c), y * z * (1 - c) - x * s],
        [z * x * (1 - c) - y * s, z * y * (1 - c) + x * s, c + z * z * (1 - c)],
    ])
    m = np.eye(4)
    m[:3, :3] = r
    return m


def look_at(origin, target, up):
    o, t, u = (np.asarray(v, float) for v in (origin, target, up))
    d = t - o
    d /= np.linalg.norm(d)
    left = np.cross(u, d)
    left /= np.linalg.norm(left)
    new_up = np.cross(d, left)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = left, new_up, d, o
    return m


def one_op(op):
    (key, val), = op.items()
    m = np.eye(4)
    if key == "scale":
        m[:3, :3] = np.diag(rgb(val))
    elif key == "translate":
        m[:3, 3] = val
    elif key == "rotate":
        m = rotation(val["axis"], val["angle"])
    elif key == "matrix":
        m = np.asarray(val, float)
    elif key == "look_at":
        m = look_at(val["origin"], val["target"], val.get("up", [0, 1, 0]))
    else:
        raise ValueError(f"unknown transform operation {key}")
    return m


def transform(t):
    """striae's transform syntax: a list applied in order (first acts first), or one op."""
    if t is None:
        return np.eye(4)
    ops = t if isinstance(t, list) else [t]
    m = np.eye(4)
    for op in ops:
        m = one_op(op) @ m
    return m


def material(mi, m, base="."):
    """Mitsuba's BSDF for a striae material. striae's opaque materials (diffuse, conductor)
    reflect on both sides of a surface, Mitsuba's only on the front: they are wrapped in
    `twosided` (it matters where a path reaches a back face, e.g. through the teapot's lid gap)."""
    d = material_one_sided(mi, m, base)
    return d if d["type"].endswith("dielectric") else {"type": "twosided", "bsdf": d}


def material_one_sided(mi, m, base):
    kind = m["type"]
    rough = float(m.get("roughness", 0.0))
    if kind == "diffuse":
        r = m.get("reflectance", 0.5)
        if isinstance(r, dict) and r.get("type") == "checkerboard":
            s = float(r.get("scale", 1.0))
            tex = {"type": "checkerboard", "color0": {"type": "rgb", "value": rgb(r["color0"])},
                   "color1": {"type": "rgb", "value": rgb(r["color1"])},
                   "to_uv": mi.ScalarTransform4f().scale([s, s, 1.0])}
            return {"type": "diffuse", "reflectance": tex}
        if isinstance(r, dict) and r.get("type") == "image":
            # striae: bilinear between pixel centres, wrapping, row 0 at v = 0, PNG decoded from
            # sRGB unless `srgb = false`, EXR linear: Mitsuba's `bitmap` with the same settings.
            path = os.path.join(base, r["path"])
            srgb = r.get("srgb", True) and path.lower().endswith(".png")
            s = float(r.get("scale", 1.0))
            tex = {"type": "bitmap", "filename": path, "raw": not srgb, "filter_type": "bilinear",
                   "wrap_mode": "repeat", "to_uv": mi.ScalarTransform4f().scale([s, s, 1.0])}
            return {"type": "diffuse", "reflectance": tex}
        if isinstance(r, dict):
            raise ValueError(f"texture {r.get('type')} is not translated")
        return {"type": "diffuse", "reflectance": {"type": "rgb", "value": rgb(r)}}
    if kind == "dielectric":
        d = {"int_ior": float(m.get("ior", 1.5)), "ext_ior": float(m.get("ext_ior", 1.0))}
        if rough > 0:
            d.update(type="roughdielectric", distribution="ggx", alpha=rough)
        else:
            d["type"] = "dielectric"
        return d
    if kind == "conductor":
        if "preset" in m:
            eta, k = next(v for names, v in PRESETS.items() if m["preset"].lower() in names)
        else:
            eta, k = m["eta"], m["k"]
        d = {"eta": {"type": "rgb", "value": rgb(eta)}, "k": {"type": "rgb", "value": rgb(k)}}
        if rough > 0:
            d.update(type="roughconductor", distribution="ggx", alpha=rough)
        else:
            d["type"] = "conductor"
        return d
    raise ValueError(f"material type {kind} is not translated")


def scene_dict(mi, path, striae_bin, res=None, spp=None, seed=None, sampler="independent"):
    with open(path, "rb") as f:
        sc = tomllib.load(f)
    base = os.path.dirname(os.path.abspath(path))
    r = sc.get("render", {})
    width, height = res or (r.get("width", 512), r.get("height", 384))
    cam = sc["camera"]
    sensor = {
        "type": "thinlens" if cam.get("aperture_radius", 0) > 0 else "perspective",
        "fov": float(cam["fov"]), "fov_axis": "y",
        "to_world": mi.ScalarTransform4f().look_at(origin=cam["position"], target=cam["look_at"],
                                                   up=cam.get("up", [0, 1, 0])),
        "film": {"type": "hdrfilm", "width": int(width), "height": int(height),
                 "rfilter": {"type": "box"}, "pixel_format": "rgb"},
        "sampler": {"type": sampler, "sample_count": int(spp or r.get("spp", 64)),
                    "seed": int(seed if seed is not None else r.get("seed", 0))},
    }
    if sensor["type"] == "thinlens":
        sensor["aperture_radius"] = float(cam["aperture_radius"])
        sensor["focus_distance"] = float(cam.get("focus_distance",
                                                 np.linalg.norm(np.subtract(cam["look_at"], cam["position"]))))
    max_depth = int(r.get("max_depth", 16))
    d = {"type": "scene",
         "integrator": {"type": "path", "max_depth": -1 if max_depth == 0 else max_depth,
                        "rr_depth": int(r.get("rr_depth", 5))},
         "sensor": sensor}
    mats = {name: material(mi, m, base) for name, m in sc.get("materials", {}).items()}
    shapes = sc.get("shapes", [])
    mesh_dir = None
    if any(s["type"] in ("teapot", "mesh", "box") for s in shapes):
        mesh_dir = tempfile.mkdtemp(prefix="striae-mi-")
        subprocess.run([striae_bin, "render", path, "--export-meshes", mesh_dir], check=True,
                       stderr=subprocess.DEVNULL)
    for i, s in enumerate(shapes):
        m = transform(s.get("transform"))
        kind = s["type"]
        if kind in ("teapot", "mesh", "box"):
            obj = os.path.join(mesh_dir, f"shape-{i}.obj")
            sh = {"type": "obj", "filename": obj}
            # Mitsuba computes smooth vertex normals for an OBJ without any; striae shades such a
            # mesh flat, so ask Mitsuba for face normals too.
            with open(obj) as f:
                if not any(line.startswith("vn ") for line in f):
                    sh["face_normals"] = True
        elif kind == "rectangle":
            sh = {"type": "rectangle", "to_world": mi.ScalarTransform4f(m.tolist())}
        elif kind == "sphere":
            c = np.asarray(s.get("center", [0, 0, 0]), float)
            scale = np.linalg.norm(m[:3, 0])
            sh = {"type": "sphere", "center": (m @ np.append(c, 1.0))[:3].tolist(),
                  "radius": float(s.get("radius", 1.0)) * scale}
        else:
            raise ValueError(kind)
        sh["bsdf"] = mats[s["material"]] if "material" in s else \
            {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.0, 0.0, 0.0]}}
        if "emission" in s:
            sh["emitter"] = {"type": "area", "radiance": {"type": "rgb", "value": rgb(s["emission"])}}
        d[f"shape_{i}"] = sh
    env = sc.get("environment")
    if env:
        if env["type"] == "constant":
            d["environment"] = {"type": "constant", "radiance": {"type": "rgb", "value": rgb(env["radiance"])}}
        else:
            d["environment"] = {"type": "envmap", "filename": os.path.join(base, env["path"]),
                                "scale": float(env.get("scale", 1.0)),
                                "to_world": mi.ScalarTransform4f(transform(env.get("transform")).tolist())}
    for j, l in enumerate(sc.get("lights", [])):
        d[f"sun_{j}"] = {"type": "directional", "direction": (-np.asarray(l["direction"], float)).tolist(),
                         "irradiance": {"type": "rgb", "value": rgb(l["irradiance"])}}
    return d


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene")
    ap.add_argument("-o", "--output", required=True, help="EXR file to write")
    ap.add_argument("--spp", type=int)
    ap.add_argument("--res", help="WIDTHxHEIGHT")
    ap.add_argument("--seed", type=int)
    ap.add_argument("--variant", default="scalar_rgb")
    ap.add_argument("--sampler", default="independent",
                    help="Mitsuba sampler plugin: independent (default), stratified, multijitter, ldsampler, ...")
    ap.add_argument("--striae", default=os.path.join(os.path.dirname(__file__), "..", "target", "release", "striae"))
    a = ap.parse_args()
    import mitsuba as mi
    mi.set_variant(a.variant)
    res = tuple(int(x) for x in a.res.lower().split("x")) if a.res else None
    scene = mi.load_dict(scene_dict(mi, a.scene, a.striae, res, a.spp, a.seed, a.sampler))
    import time
    t0 = time.time()
    img = mi.render(scene, seed=a.seed or 0)
    mi.Bitmap(img).write(a.output)
    dt = time.time() - t0
    h, w = np.asarray(img).shape[:2]
    n = w * h * (a.spp or scene.sensors()[0].sampler().sample_count())
    print(f"mitsuba {a.variant}: {dt:.2f} s, {n / dt / 1e6:.3f} M samples/s, mean {np.asarray(img).mean(axis=(0, 1))}",
          file=sys.stderr)


if __name__ == "__main__":
    main()
