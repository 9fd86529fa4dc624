#!/usr/bin/env python3
"""Cost per sample of scratched glass over smooth glass on the same scene (BENCHMARKS.md,
"Scratched glass over smooth glass": target at most 1.3x).

For each scene (a scratched-glass scene file whose glass material is `[materials.glass]`), the
script writes variants of it: `smooth` (the glass swapped for `type = "dielectric"` with the same
`ior`), and the scratched material with each coverage mode (`footprint`, the default; `sample`;
`point`), and `dielectric`: the scratches with dielectric walls (METHOD.md 8.2, the 2D table's
keys dropped; smooth walls, traced), whose ratio to `footprint` is the complete glass model's cost
over the seed's, and `dielectric-table`: the same with `lobes = "table"`. It renders each with one thread and measures the CPU time (user + sys) of
`--spp SPP` minus that of `--spp 1`, so that the set-up (table, layers, BVH) cancels, and prints
the medians over interleaved rounds and the ratios to `smooth`, with the compiled copy of the
render loop that ran (the CPU's widest; `STRIAE_SIMD=avx2` or `portable` in the environment
caps it).

    python3 scripts/scratched_cost.py scenes/glass-teapot-setting1.toml \\
        scenes/glass-plate-closeup.toml --spp 64 --rounds 2

`--paired REF` measures on a busy machine instead: each round runs every other kind at the same
time as `REF`, the two pinned to CPUs 0 and 1, then again with the CPUs swapped, and takes the
geometric mean of the two ratios of their render times (the "done in" the renderer prints,
set-up excluded): what else loads the machine at the time slows both runs of a pair alike, and
a CPU slower than the other slows each kind once. It prints the median over the rounds of each
kind's ratio to `REF` (needs Linux's `taskset` and two CPUs).

    python3 scripts/scratched_cost.py scenes/glass-plate-setting1.toml --spp 32 \\
        --res 256x192 --rounds 11 --kinds footprint dielectric --paired footprint
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
    if kind in ("dielectric", "dielectric-table"):
        table_keys = r"^(walls|fresnel|fresnel_law|ior|m|n|nr|albedo|max_bounces) = .*\n"
        head, _, scratches = m.group(1).partition("[materials.glass.scratches]\n")
        walls = 'walls = "dielectric"\n' + ('lobes = "table"\n' if kind == "dielectric-table" else "")
        body = head + '[materials.glass.scratches]\n' + walls + re.sub(
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
    ap.add_argument("--paired", metavar="REF", help="the kind each other kind runs beside")
    args = ap.parse_args()
    if args.paired and args.paired not in args.kinds:
        sys.exit(f"--paired {args.paired}: not one of --kinds")
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
                if args.paired:
                    report_paired(args, name, files, env, tmp, copies)
                    continue
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
            if args.paired:
                continue
            med = {k: statistics.median(v) for k, v in times.items()}
            ref = med.get("smooth")
            loop = ", ".join(copies) or "unknown"
            print(f"{name} ({args.res}, {args.spp} spp, 1 thread, {loop} render loop, "
                  f"CPU s over {args.rounds} rounds):")
            for kind in args.kinds:
                ratio = f" ({med[kind] / ref:.2f}x)" if ref else ""
                print(f"  {kind:10s} {med[kind]:7.2f} s{ratio}")


def render_seconds(proc):
    """The render time a finished `striae render` printed ("done in X s")."""
    err = proc.stderr.read().decode()
    m = re.search(r"done in ([0-9.]+) s", err)
    if proc.returncode != 0 or not m:
        sys.exit(f"failed: {' '.join(proc.args)}\n{err}")
    return float(m.group(1))


def report_paired(args, name, files, env, tmp, copies):
    """`--paired`: each kind's render time over `args.paired`'s, run side by side."""
    ratios = {k: [] for k in args.kinds if k != args.paired}
    for _ in range(args.rounds):
        for kind in ratios:
            product = 1.0
            for cpus in ((0, 1), (1, 0)):
                procs = []
                for cpu_id, k in zip(cpus, (args.paired, kind)):
                    cmd = ["taskset", "-c", str(cpu_id), args.striae, "render", files[k], "--threads",
                           "1", "--res", args.res, "--spp", str(args.spp), "-o",
                           os.path.join(tmp, f"{cpu_id}.exr")]
                    procs.append(subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL,
                                                  stderr=subprocess.PIPE))
                for p in procs:
                    p.wait()
                ref, t = (render_seconds(p) for p in procs)
                product *= t / ref
            ratios[kind].append(product ** 0.5)
    loop = ", ".join(copies) or "unknown"
    print(f"{name} ({args.res}, {args.spp} spp, 1 thread each, side by side with {args.paired}, "
          f"{loop} render loop, {args.rounds} rounds of 2):")
    for kind, v in ratios.items():
        spread = " ".join(f"{x:.2f}" for x in sorted(v))
        print(f"  {kind:16s} {statistics.median(v):5.2f}x {args.paired}  [{spread}]")


if __name__ == "__main__":
    main()
