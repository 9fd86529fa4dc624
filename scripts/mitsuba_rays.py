#!/usr/bin/env python3
"""How many rays Mitsuba 3 traces a sample, against striae, on the same scene (BENCHMARKS.md,
"Rays a sample and ray queries against Embree").

A render's speed is its rays a sample times its cost a ray, plus the shading. This counts the
first factor for Mitsuba: `scripts/embree_count.c` (built here with gcc) is preloaded into
`scripts/mitsuba_scene.py` and counts every closest-hit and shadow query Mitsuba hands to its
Embree, packet lanes included. striae's count is the one `striae render` prints. With
`--dump FILE` the preloaded library also keeps the rays of the first render thread's 16-wide
closest-hit calls (every `--dump-every`-th call, in call order: Mitsuba's own wavefront order)
in `scripts/bench_traversal.py`'s ray format, so the traversal can be timed on exactly the
rays Mitsuba traces.

    DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM-19.so \\
    python3 scripts/mitsuba_rays.py scenes/glass-teapot.toml --spp 16 \\
        [--variants scalar_rgb llvm_ad_rgb] [--dump rays.f32 --dump-every 8]
"""
import argparse
import os
import re
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))


def build_shim(tmp):
    """Compile `embree_count.c` into `tmp`; the path of the shared library."""
    lib = os.path.join(tmp, "embree_count.so")
    p = subprocess.run(["gcc", "-O2", "-shared", "-fPIC", "-o", lib, os.path.join(HERE, "embree_count.c"),
                        "-ldl", "-lpthread"], capture_output=True, text=True)
    if p.returncode != 0:
        sys.exit(f"building embree_count.c failed:\n{p.stderr}")
    return lib


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene")
    ap.add_argument("--spp", type=int, required=True)
    ap.add_argument("--res", help="WIDTHxHEIGHT (default: the scene's)")
    ap.add_argument("--variants", nargs="+", default=["scalar_rgb", "llvm_ad_rgb"])
    ap.add_argument("--striae", default=os.path.join(HERE, "..", "target", "release", "striae"))
    ap.add_argument("--dump", help="keep rays of the last variant's render in this file")
    ap.add_argument("--dump-every", type=int, default=8, help="keep every N-th 16-wide call")
    a = ap.parse_args()
    import mitsuba
    embree = os.path.join(os.path.dirname(mitsuba.__file__), "libembree3.so")
    if not os.path.exists(embree):
        sys.exit(f"{embree}: not found (this Mitsuba wheel does not ship Embree 3)")
    with tempfile.TemporaryDirectory() as tmp:
        # striae first: its output names the resolution (the scene's unless `--res`) and the rays.
        p = subprocess.run([a.striae, "render", a.scene, "--spp", str(a.spp), "-o", os.path.join(tmp, "st")]
                           + (["--res", a.res] if a.res else []), capture_output=True, text=True)
        size = re.search(r" at (\d+)x(\d+), ", p.stdout + p.stderr)
        rays = re.search(r"\((\d+) rays", p.stdout + p.stderr)
        if p.returncode != 0 or not size or not rays:
            sys.exit(f"striae failed:\n{p.stdout}{p.stderr}")
        w, h = int(size.group(1)), int(size.group(2))
        samples = w * h * a.spp
        shim = build_shim(tmp)
        print(f"{a.scene}, {w}x{h}, {a.spp} spp ({samples} samples); rays a sample")
        print(f"{'renderer':22s} {'closest-hit':>12s} {'shadow':>8s} {'total':>8s} {'lanes/call':>11s}")
        for i, v in enumerate(a.variants):
            counts = os.path.join(tmp, f"{v}.txt")
            env = dict(os.environ, LD_PRELOAD=shim, EMBREE_LIB=embree, RAYCOUNT_OUT=counts)
            dumping = a.dump and i == len(a.variants) - 1
            if dumping:
                env.update(DUMP_FILE=os.path.abspath(a.dump), DUMP_EVERY=str(a.dump_every))
            p = subprocess.run([sys.executable, os.path.join(HERE, "mitsuba_scene.py"), a.scene, "-o",
                                os.path.join(tmp, f"{v}.exr"), "--spp", str(a.spp), "--variant", v,
                                "--striae", a.striae, "--res", f"{w}x{h}"], env=env, capture_output=True, text=True)
            if p.returncode != 0 or not os.path.exists(counts):
                sys.exit(f"mitsuba {v} failed:\n{p.stdout}{p.stderr}")
            lines = [dict(zip(*[iter(line.split())] * 2)) for line in open(counts).read().splitlines()]
            if len(lines) != 1:
                sys.exit(f"{counts}: expected one process that traced rays, got {len(lines)}")
            c = {k: int(x) for k, x in lines[0].items()}
            hit, shadow = c["intersect"] / samples, c["occluded"] / samples
            per_call = f"{(c['intersect'] + c['occluded']) / c['packet_calls']:.1f}" if c["packet_calls"] else "-"
            print(f"{'mitsuba ' + v:22s} {hit:12.3f} {shadow:8.3f} {hit + shadow:8.3f} {per_call:>11s}")
            if dumping:
                print(f"  kept {c['lanes_in_dump']} rays of {v} in {a.dump}")
        print(f"{'striae':22s} {'-':>12s} {'-':>8s} {int(rays.group(1)) / samples:8.3f} {'-':>11s}")

if __name__ == "__main__":
    main()
