#!/usr/bin/env python3
"""Interleaved speed comparison of striae and Mitsuba 3 on one scene (BENCHMARKS.md,
"Render speed against Mitsuba 3": target at least `llvm_ad_rgb`'s speed on the glass teapot).

Runs, round after round, `striae render` (one or more binaries) and `scripts/mitsuba_scene.py`
for each Mitsuba variant, all at the same spp and resolution, and prints per renderer the
median samples/s (as each renderer reports it: render time including writing the EXR for
Mitsuba, the render loop for striae), the median CPU time (user + sys, from /usr/bin/time) and
the CPU samples/s. Interleaving spreads the load of a shared machine over all renderers.
striae runs once per `--samplers` kind (default: its Sobol sampler and the `independent` one
that the Mitsuba scene uses, so one row compares equal samplers), Mitsuba once per
`--mitsuba-samplers` plugin (default `independent`).

    DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM-19.so \\
    python3 scripts/bench_render.py scenes/glass-teapot.toml --spp 64 --rounds 3 \\
        --striae target/release/striae --variants scalar_rgb llvm_ad_rgb
"""
import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))


def timed(cmd):
    """Run `cmd` under /usr/bin/time; return (combined stderr+stdout, cpu seconds)."""
    p = subprocess.run(["/usr/bin/time", "-f", "CPU %U %S"] + cmd, capture_output=True, text=True)
    out = p.stdout + p.stderr
    if p.returncode != 0:
        sys.exit(f"failed: {' '.join(cmd)}\n{out}")
    u, s = re.findall(r"CPU ([0-9.]+) ([0-9.]+)", out)[-1]
    return out, float(u) + float(s)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene")
    ap.add_argument("--spp", type=int, required=True)
    ap.add_argument("--res", default="512x384")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--striae", nargs="+", default=[os.path.join(HERE, "..", "target", "release", "striae")])
    ap.add_argument("--variants", nargs="*", default=["scalar_rgb", "llvm_ad_rgb"])
    ap.add_argument("--samplers", nargs="+", default=["sobol", "independent"],
                    help="striae's render.sampler kinds to run")
    ap.add_argument("--mitsuba-samplers", nargs="+", default=["independent"],
                    help="Mitsuba sampler plugins to run each variant with (e.g. independent multijitter)")
    a = ap.parse_args()
    tmp = tempfile.mkdtemp()
    w, h = (int(x) for x in a.res.split("x"))
    n = w * h * a.spp
    runs = {}
    for r in range(a.rounds):
        for b in a.striae:
            for sampler in a.samplers:
                out, cpu = timed([b, "render", a.scene, "--spp", str(a.spp), "--res", a.res, "-q",
                                  "--sampler", sampler, "-o", os.path.join(tmp, "st")])
                m = re.search(r"done in ([0-9.]+) s: ([0-9.]+) M samples/s, ([0-9.]+) M rays/s", out)
                copy = re.search(r"rays, (.+?) render loop\)", out)
                name = f"striae {b} ({sampler}, {copy[1] if copy else 'unknown'} render loop)"
                runs.setdefault(name, []).append((float(m[2]), float(m[3]), cpu))
        for v in a.variants:
            for sampler in a.mitsuba_samplers:
                out, cpu = timed([sys.executable, os.path.join(HERE, "mitsuba_scene.py"), a.scene, "-o",
                                  os.path.join(tmp, f"mi_{v}.exr"), "--spp", str(a.spp), "--variant", v,
                                  "--res", a.res, "--sampler", sampler])
                m = re.search(r"([0-9.]+) M samples/s", out)
                runs.setdefault(f"mitsuba {v} ({sampler})", []).append((float(m[1]), float("nan"), cpu))
        print(f"round {r + 1}: " + ", ".join(f"{k}: {v[-1][0]:.3f} M/s, {v[-1][2]:.2f} s CPU"
                                             for k, v in runs.items()), flush=True)
    print(f"\nmedians over {a.rounds} rounds, {a.res}, {a.spp} spp ({n / 1e6:.2f} M samples):")
    print("| renderer | samples/s | rays/s | CPU time | samples per CPU-second |")
    print("|---|---|---|---|---|")
    for k, v in runs.items():
        sps = statistics.median(x[0] for x in v)
        rps = statistics.median(x[1] for x in v)
        cpu = statistics.median(x[2] for x in v)
        rays = "-" if rps != rps else f"{rps:.2f} M"
        per_cpu = f"{n / cpu / 1e6:.3f} M" if cpu > 0 else "-"  # (too short to time)
        print(f"| {k} | {sps:.3f} M | {rays} | {cpu:.2f} s | {per_cpu} |")


if __name__ == "__main__":
    main()
