#!/usr/bin/env python3
"""Ray queries alone, striae against Mitsuba 3 (Embree) on the same rays (BENCHMARKS.md,
"Rays a sample and ray queries against Embree").

`scripts/bench_render.py` compares whole renders; this separates the BVH from the rest of the
path tracer. The scene is described to Mitsuba by `scripts/mitsuba_scene.py` (the same
triangles: teapots and meshes go through striae's `--export-meshes`). Three ray sets:

* camera: one jittered camera ray per pixel (coherent), listed by blocks of 8 x 4 pixels;
* pixels: as many camera rays, 32 through each of the pixels at those blocks' centres (the
  samples of a pixel, as the render loop traces them);
* secondary: from each camera ray's first hit, a uniformly random direction, the origin pushed
  off the surface as striae's `offset_origin` does (incoherent, like a path's later bounces).

Both renderers run every query on the same rays, on one thread, `--repeats` times; the median
is quoted. Mitsuba's `intersect` builds the full `SurfaceInteraction` (striae's the full
`SurfaceHit`), its `preliminary` only the hit distance and primitive, `occluded` is the any-hit
query (`ray_test`). striae's `intersect_packets` is its `intersect` on runs of 32 consecutive
rays traced together where they share an origin (`Geometry::intersect_coherent`, what the
render loop does with a pixel's camera rays: in the `pixels` set, one pixel; in `camera`, a
block of 8 x 4 pixels), set against Mitsuba's
`intersect`; secondary rays share no origin and fall back to one at a time. The hit counts must
agree; the script stops if they do not.

With `--rays FILE` the sets are instead the rays of a file, in its order (`file`) and shuffled
(`shuffled`): `scripts/mitsuba_rays.py --dump` keeps the rays of a Mitsuba render in the order
its wavefront traces them (16 samples of one pixel a packet), so the two sets show how much
each traversal gains from that order. Mitsuba's LLVM variants hand Embree the rays of an array
in packets of 16 consecutive rays (`rtcIntersect16`), as in its renders.

    cargo build --release && cargo build --release -p striae --example trace_rays
    DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM-19.so \\
        python3 scripts/bench_traversal.py scenes/glass-teapot.toml [--variant llvm_ad_rgb]
"""
import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.join(HERE, "..")


def rays_of(scene, mi, res, seed):
    """The ray sets, as (origins, directions) float32 arrays: `camera`, `pixels`, `secondary`."""
    w, h = res
    n = w * h
    rng = np.random.default_rng(seed)
    sensor = scene.sensors()[0]

    def camera(px, py):
        """Camera rays through the pixels (px, py), each at a uniform point of its pixel."""
        fx = (px + rng.random(len(px))) / w
        fy = (py + rng.random(len(py))) / h
        ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(fx.astype(np.float32), fy.astype(np.float32)),
                                   mi.Point2f(0.5, 0.5))
        o = np.stack([np.array(ray.o.x), np.array(ray.o.y), np.array(ray.o.z)], 1)
        d = np.stack([np.array(ray.d.x), np.array(ray.d.y), np.array(ray.d.z)], 1)
        return o.astype(np.float32), d.astype(np.float32)

    # One ray per pixel, the pixels in blocks of 8 x 4, so that runs of 32 rays are blocks.
    idx = np.arange(n)
    x, y = idx % w, idx // w
    idx = idx[np.lexsort((x % 8, y % 4, x // 8, y // 4))]
    o, d = camera(idx % w, idx // w)
    # 32 rays through each of the pixels at the centres of those blocks (as many rays): a run
    # of 32 is one pixel's, the render loop's packet.
    cx = np.repeat(np.arange(w // 8) * 8 + 4, 32)
    cy = np.arange(h // 4) * 4 + 2
    px, py = np.tile(cx, len(cy)), np.repeat(cy, len(cx))
    op, dp = camera(px, py)
    si = scene.ray_intersect(mi.Ray3f(mi.Point3f(*o.T), mi.Vector3f(*d.T)))
    valid = np.array(si.is_valid())
    p = np.stack([np.array(si.p.x), np.array(si.p.y), np.array(si.p.z)], 1)[valid]
    ng = np.stack([np.array(si.n.x), np.array(si.n.y), np.array(si.n.z)], 1)[valid]
    v = rng.normal(size=(len(p), 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    side = np.where(np.sum(v * ng, 1, keepdims=True) >= 0.0, 1.0, -1.0)
    eps = 1e-4 * (1.0 + np.abs(p).max(1, keepdims=True))
    o2 = p + eps * ng * side
    return {"camera": (o, d), "pixels": (op, dp),
            "secondary": (o2.astype(np.float32), v.astype(np.float32))}


def time_mitsuba(scene, mi, dr, o, d, repeats):
    """{query: (median seconds, hits)} for Mitsuba on one thread."""
    rays = mi.Ray3f(mi.Point3f(*o.T), mi.Vector3f(*d.T))
    queries = {
        "preliminary": lambda: scene.ray_intersect_preliminary(rays),
        "intersect": lambda: scene.ray_intersect(rays),
        "occluded": lambda: scene.ray_test(rays),
    }
    out = {}
    for name, q in queries.items():
        seconds = []
        for _ in range(repeats + 1):  # the first run compiles the kernel
            dr.sync_thread()
            start = time.perf_counter()
            r = q()
            dr.eval(r)
            dr.sync_thread()
            seconds.append(time.perf_counter() - start)
        hit = r if name == "occluded" else r.is_valid()
        out[name] = (statistics.median(seconds[1:]), int(np.count_nonzero(np.array(hit))))
    return out


def time_striae(example, scene_path, o, d, repeats, tmp):
    """{query: (median seconds, hits)} for striae's `trace_rays` example."""
    path = os.path.join(tmp, "rays.f32")
    np.concatenate([o, d], 1).astype("<f4").tofile(path)
    p = subprocess.run([example, scene_path, path, str(repeats)], capture_output=True, text=True)
    if p.returncode != 0:
        sys.exit(f"{example} failed:\n{p.stdout}{p.stderr}")
    out = {}
    for line in p.stdout.splitlines():
        kv = dict(re.findall(r"(\w+)=(\S+)", line))
        out[kv["query"]] = (float(kv["seconds"]), int(kv["hits"]))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene")
    ap.add_argument("--res", default="512x384", help="camera rays: one per pixel at this resolution")
    ap.add_argument("--variant", default="llvm_ad_rgb")
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--rays", help="instead, rays from this file (six little-endian f32 a ray, e.g. from "
                    "`mitsuba_rays.py --dump`): set `file` in the file's order, set `shuffled` permuted")
    ap.add_argument("--striae", default=os.path.join(ROOT, "target", "release", "striae"))
    ap.add_argument("--example", default=os.path.join(ROOT, "target", "release", "examples", "trace_rays"))
    a = ap.parse_args()
    for f in (a.striae, a.example):
        if not os.path.exists(f):
            sys.exit(f"{f} not found: run `cargo build --release` and "
                     "`cargo build --release -p striae --example trace_rays`")
    import drjit as dr
    import mitsuba as mi
    sys.path.insert(0, HERE)
    import mitsuba_scene

    mi.set_variant(a.variant)
    res = tuple(int(x) for x in a.res.split("x"))
    scene = mi.load_dict(mitsuba_scene.scene_dict(mi, a.scene, a.striae, res, 1, 0))
    dr.set_thread_count(1)
    tmp = tempfile.mkdtemp()
    print(f"{a.scene}, one thread, medians of {a.repeats}; Mitsuba {mi.__version__} {a.variant}")
    print(f"{'rays':10s} {'query':18s} {'count':>8s} {'hits':>8s} {'striae Mrays/s':>15s} "
          f"{'Mitsuba Mrays/s':>16s} {'striae/Mitsuba':>15s}")
    if a.rays:
        r = np.fromfile(a.rays, dtype="<f4").reshape(-1, 6)
        shuffled = r[np.random.default_rng(a.seed).permutation(len(r))]
        sets = {name: (np.ascontiguousarray(x[:, :3]), np.ascontiguousarray(x[:, 3:]))
                for name, x in (("file", r), ("shuffled", shuffled))}
    else:
        sets = rays_of(scene, mi, res, a.seed)
    for name, (o, d) in sets.items():
        m = time_mitsuba(scene, mi, dr, o, d, a.repeats)
        s = time_striae(a.example, a.scene, o, d, a.repeats, tmp)
        n = len(o)
        for query in ("preliminary", "intersect", "intersect_packets", "occluded"):
            mt, mh = m["intersect" if query == "intersect_packets" else query]
            rate_m = n / mt / 1e6
            if query in s:
                st, sh = s[query]
                if sh != mh:
                    sys.exit(f"{name} {query}: striae hits {sh} rays, Mitsuba {mh}: not the same scene")
                rate_s = n / st / 1e6
                print(f"{name:10s} {query:18s} {n:8d} {mh:8d} {rate_s:15.2f} {rate_m:16.2f} {rate_s / rate_m:15.2f}")
            else:
                print(f"{name:10s} {query:18s} {n:8d} {mh:8d} {'-':>15s} {rate_m:16.2f} {'-':>15s}")


if __name__ == "__main__":
    main()
