#!/usr/bin/env python3
"""Cost per sample of scratched glass over smooth glass on the same scene (BENCHMARKS.md,
"Scratched glass over smooth glass": target at most 1.3x).

For each scene (a scratched-glass scene file whose glass material is `[materials.glass]`), the
script writes variants of it: `smooth` (the glass swapped for `type = "dielectric"` with the same
`ior`), and the scratched material with each coverage mode (`footprint`, the default; `sample`;
`point`), and `dielectric`: the scratches with dielectric walls (METHOD.md 8.2, the 2D table's
keys dropped), whose ratio to `footprint` is the complete glass model's cost over the seed's. It renders each with one thread and measures the CPU time (user + sys) of
`--spp SPP` minus that of `--spp 1`, so that the set-up (table, layers, BVH) cancels, and prints
the medians over interleaved rounds and the ratios to `smooth`, with the compiled copy of the
render loop that ran (the CPU's widest; `STRIAE_SIMD=avx2` or `portable` in the environment
caps it).

    python3 scripts/scratched_cost.py scenes/glass-teapot-setting1.toml \\
        scenes/glass-plate-closeup.toml --spp 64 --rounds 2
"""
import argparse
import os
import re
import resource
import statistics
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))


def variant(text, kind):
    """The scene text with its glass material as `kind`."""
    m = re.search(r"\[materials\.glass\]\n(.*?)(?=\n\[\[|\Z)", text, flags=re.S)
    if not m or 'type = "scratched"' not in m.group(1):
        sys.exit("expected a scratched [materials.glass] section")
    if kind == "smooth":
        ior = re.search(r"^ior = ([0-9.]+)", m.group(1), flags=re.M)
        body = f'type = "dielectric"\nior = {ior.group(1) if ior else 1.5}\n'
        return text[: m.start(1)] + body + text[m.end(1):]
    if kind == "dielectric":
        table_keys = r"^(walls|fresnel|fresnel_law|ior|m|n|nr|albedo|max_bounces) = .*\n"
        head, _, scratches = m.group(1).partition("[materials.glass.scratches]\n")
        body = head + '[materials.glass.scratches]\nwalls = "dielectric"\n' + re.sub(
            table_keys, "", scratches, flags=re.M)
        return text[: m.start(1)] + body + text[m.end(1):]
    body = re.sub(r'^coverage = .*\n', "", m.group(1), flags=re.M)
    body = body.rstrip("\n") + f'\ncoverage = "{kind}"\n'
    return text[: m.start(1)] + body + text[m.end(1):]


def cpu(cmd, env, output=None):
    """CPU seconds (user + sys) of `cmd`; its stderr appended to the list `output` if given."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    p = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if p.returncode != 0:
        sys.exit(f"failed: {' '.join(cmd)}\n{p.stdout}{p.stderr}")
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if output is not None:
        output.append(p.stderr)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scenes", nargs="+")
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--res", default="512x384")
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--striae", default=os.path.join(HERE, "..", "target", "release", "striae"))
    ap.add_argument("--kinds", nargs="+", default=["smooth", "footprint", "sample", "point"])
    args = ap.parse_args()
    env = dict(os.environ)
    with tempfile.TemporaryDirectory() as tmp:
        env.setdefault("STRIAE_CACHE", os.path.join(tmp, "cache"))
        for scene in args.scenes:
            text = open(scene).read()
            name = os.path.splitext(os.path.basename(scene))[0]
            files = {}
            for kind in args.kinds:
                # Next to the original, so relative paths in it still resolve.
                path = os.path.join(os.path.dirname(os.path.abspath(scene)), f".{name}-{kind}.toml")
                with open(path, "w") as f:
                    f.write(variant(text, kind))
                files[kind] = path
            try:
                # Warm-up: the scratch table is computed (or read) once, outside the timings.
                warm = []
                for kind in args.kinds:
                    cpu([args.striae, "render", files[kind], "--threads", "1", "--res", "8x8", "--spp", "1",
                         "-q", "-o", os.path.join(tmp, "warm.exr")], env, warm)
                # Which compiled copy of the render loop ran (the CPU's widest, or STRIAE_SIMD's).
                copies = sorted(set(re.findall(r"rays, (.+?) render loop\)", "".join(warm))))
                times = {k: [] for k in args.kinds}
                for _ in range(args.rounds):
                    for kind in args.kinds:
                        base = [args.striae, "render", files[kind], "--threads", "1", "--res", args.res,
                                "-q", "-o", os.path.join(tmp, f"{name}-{kind}.exr")]
                        t = cpu(base + ["--spp", str(args.spp)], env) - cpu(base + ["--spp", "1"], env)
                        times[kind].append(t)
            finally:
                for path in files.values():
                    os.remove(path)
            med = {k: statistics.median(v) for k, v in times.items()}
            ref = med.get("smooth")
            loop = ", ".join(copies) or "unknown"
            print(f"{name} ({args.res}, {args.spp} spp, 1 thread, {loop} render loop, "
                  f"CPU s over {args.rounds} rounds):")
            for kind in args.kinds:
                ratio = f" ({med[kind] / ref:.2f}x)" if ref else ""
                print(f"  {kind:10s} {med[kind]:7.2f} s{ratio}")


if __name__ == "__main__":
    main()
