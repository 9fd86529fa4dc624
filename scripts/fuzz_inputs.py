#!/usr/bin/env python3
"""Random fuzzing of what striae reads: scene files and the files they name.

`tests/robustness.rs` replaces every value of two scenes systematically; this script goes
further at random, for as long as it is given. It flags any run that panics, dies on a signal or
runs past a time limit, any failure whose message does not name the file at fault, and any
failure that leaves an output file behind.

* `scenes`: the shipped scenes (their scratch tables shrunk to M 32, N 300, N_r 5, so that
  tables compute in milliseconds) and `crates/striae/tests/data/every-kind.toml` (every shape,
  material, light and file kind), with one to eight random mutations each: values replaced by
  NaN, infinities, extremes, wrong types, empty or unknown strings; keys deleted, misspelt or
  added; lists cut or lengthened.
* `files`: the OBJ mesh, the EXR environment map, the PNG texture, a scratch table (`.npz`) and
  a profile file, truncated, with bytes flipped or inserted, emptied or replaced, read by
  `render`, `plot` and `precompute`.

    cargo build --release
    python3 scripts/fuzz_inputs.py scenes --runs 4000 --seed 1
    python3 scripts/fuzz_inputs.py files --runs 2000 --seed 1

Each flagged input is copied to the work folder (default: a temporary one, printed) as
`bad-N-...`; the script exits with status 1 if any was flagged.
"""
import argparse
import copy
import json
import math
import os
import random
import shutil
import subprocess
import sys
import tempfile
import tomllib

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.join(HERE, "..")

# Every shape, material, light, transform and input-file kind (shared with tests/robustness.rs).
DATA = os.path.join(ROOT, "crates", "striae", "tests", "data")
PROFILE = "# x z\n0 0\n1.2 -0.8\n2 -1.1\n3.1 -0.4\n4 0\n"


def run(cmd, cwd, env, timeout):
    """(exit status or "timeout", stderr)."""
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=env, cwd=cwd)
        return p.returncode, p.stderr
    except subprocess.TimeoutExpired:
        return "timeout", ""


def prepare(striae, base, env):
    """The base folder: the shipped scenes with small tables, the every-kind scene and its files."""
    os.makedirs(base, exist_ok=True)
    for name in sorted(os.listdir(os.path.join(ROOT, "scenes"))):
        text = open(os.path.join(ROOT, "scenes", name)).read()
        for key, small in (("n", "300"), ("nr", "5"), ("m", "32")):
            text = "\n".join(f"{key} = {small}" if line.startswith(f"{key} = ") else line
                             for line in text.split("\n"))
        open(os.path.join(base, name), "w").write(text)
    for name in ("every-kind.toml", "tet.obj"):
        shutil.copy(os.path.join(DATA, name), os.path.join(base, name))
    open(os.path.join(base, "prof.txt"), "w").write(PROFILE)
    for cmd in ([striae, "precompute", "--m", "16", "--n", "100", "--nr", "4", "-o", "t.npz"],
                [striae, "render", "glass-plate.toml", "--spp", "1", "--res", "8x4", "-q", "-o", "sky"]):
        rc, err = run(cmd, base, env, 120)
        if rc != 0:
            sys.exit(f"setting up {base}: {' '.join(cmd)} failed: {err}")
    shutil.copy(os.path.join(base, "sky.png"), os.path.join(base, "wood.png"))


def toml_value(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{json.dumps(k)} = {toml_value(x)}" for k, x in v.items()) + " }"
    raise TypeError(v)


def toml_text(scene):
    """A scene dictionary as TOML: tables as sections, top-level lists of tables as arrays."""
    out = []

    def table(path, t):
        for k, v in t.items():
            if not isinstance(v, dict) and not (path == [] and is_table_list(v)):
                out.append(f"{json.dumps(k)} = {toml_value(v)}")
        for k, v in t.items():
            if isinstance(v, dict):
                out.append("\n[" + ".".join(json.dumps(p) for p in path + [k]) + "]")
                table(path + [k], v)
        if path == []:
            for k, v in t.items():
                if is_table_list(v):
                    for entry in v:
                        out.append(f"\n[[{json.dumps(k)}]]")
                        out.extend(f"{json.dumps(kk)} = {toml_value(vv)}" for kk, vv in entry.items())

    table([], scene)
    return "\n".join(out) + "\n"


def is_table_list(v):
    return isinstance(v, list) and bool(v) and all(isinstance(x, dict) for x in v)


NUMBERS = [-1, 0, -0.0, float("nan"), float("inf"), -float("inf"), 1e30, 1e-30, 2**62, -2**62,
           0.5, 1.5, 1e6, 3]


def mutate_value(rng, v):
    r = rng.random()
    if isinstance(v, bool):
        return rng.choice([0, "yes", not v, []])
    if isinstance(v, (int, float)):
        if r < 0.7:
            return rng.choice(NUMBERS)
        if r < 0.8:
            return v * rng.choice([-1, 10, 1000, 0.001])
        return rng.choice(["abc", True, [], [v, v], {}])
    if isinstance(v, str):
        if r < 0.3:
            return ""
        if r < 0.5:
            return v[:-1] or "x"
        if r < 0.6:
            return v + "x"
        if r < 0.7:
            return "missing/file.obj"
        return rng.choice([1, 1.5, [], {}, "v:angle=0", "v:angle=180", "v:angle=nan", "flat",
                           "round:depth=-1", "trapezoid:depth=1,bottom=2", "file:prof.txt"])
    if isinstance(v, list):
        if not v:
            return [1.0]
        if r < 0.25:
            return v[:-1]
        if r < 0.4:
            return v + [v[-1]]
        if r < 0.5:
            return []
        if r < 0.6 and not isinstance(v[0], dict):
            return [0.0] * len(v)
        if r < 0.7:
            return [float("nan")] + v[1:]
        if r < 0.8:
            return "notalist"
        v = list(v)
        i = rng.randrange(len(v))
        v[i] = mutate_value(rng, v[i])
        return v
    if isinstance(v, dict):
        v = dict(v)
        if not v:
            return {"bogus": 1}
        k = rng.choice(list(v))
        if r < 0.35:
            del v[k]
        elif r < 0.55:
            v[k[:-1] or "z"] = v.pop(k)
        elif r < 0.7:
            v["colour"] = 1
        else:
            v[k] = mutate_value(rng, v[k])
        return v
    return v


def paths(x, prefix=()):
    yield prefix
    if isinstance(x, dict):
        for k, v in x.items():
            yield from paths(v, prefix + (k,))
    elif isinstance(x, list):
        for i, v in enumerate(x):
            yield from paths(v, prefix + (i,))


def mutate_scene(rng, scene):
    s = copy.deepcopy(scene)
    for _ in range(rng.choice([1, 1, 2, 3, 5, 8])):
        p = rng.choice([p for p in paths(s) if p])
        parent = s
        for k in p[:-1]:
            parent = parent[k]
        parent[p[-1]] = mutate_value(rng, parent[p[-1]])
    return s


def corrupt_bytes(rng, data):
    r = rng.random()
    d = bytearray(data)
    if r < 0.25 and d:
        return bytes(d[:rng.randrange(len(d))])
    if r < 0.55 and d:
        for _ in range(rng.choice([1, 2, 4, 16])):
            d[rng.randrange(len(d))] = rng.randrange(256)
        return bytes(d)
    if r < 0.65:
        return b""
    if r < 0.75 and d:
        i = rng.randrange(len(d))
        return bytes(d[:i] + bytes(rng.randrange(256) for _ in range(rng.randrange(1, 64))) + d[i:])
    if r < 0.85 and d:
        lines = bytes(d).split(b"\n")
        lines[rng.randrange(len(lines))] = rng.choice(
            [b"v 1e40 0 0", b"f 1 2 99", b"f 0 1 2", b"vn nan 0 0", b"1e39 -1", b"nan nan",
             b"f -1 -2 -3", b"vt inf 0", b"0 0", b"1 1", b"x y z"])
        return b"\n".join(lines)
    return bytes(rng.randrange(256) for _ in range(rng.randrange(1, 300)))


OUTPUTS = ("out.exr", "out.png", "plot.png", "pout.npz")
FILE_TARGETS = [
    ("tet.obj", ["render", "every-kind.toml"]),
    ("sky.exr", ["render", "every-kind.toml"]),
    ("wood.png", ["render", "every-kind.toml"]),
    ("t.npz", ["render", "every-kind.toml"]),
    ("t.npz", ["plot", "t.npz", "-o", "plot.png"]),
    ("prof.txt", ["precompute", "--profile", "file:prof.txt", "--m", "8", "--n", "50", "--nr", "2",
                  "-o", "pout.npz"]),
]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("mode", choices=["scenes", "files"])
    ap.add_argument("--runs", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--timeout", type=float, default=60.0, help="seconds per run")
    ap.add_argument("--work", help="work folder (default: a new temporary one)")
    ap.add_argument("--striae", default=os.path.join(ROOT, "target", "release", "striae"))
    a = ap.parse_args()
    striae = os.path.abspath(a.striae)
    if not os.path.exists(striae):
        sys.exit(f"{striae} not found: run `cargo build --release` first")
    work = a.work or tempfile.mkdtemp(prefix="striae-fuzz-")
    base, runs = os.path.join(work, "base"), os.path.join(work, "run")
    env = dict(os.environ, STRIAE_CACHE=os.path.join(work, "cache"), RUST_BACKTRACE="0")
    prepare(striae, base, env)
    shutil.copytree(base, runs, dirs_exist_ok=True)
    print(f"work folder: {work}")
    rng = random.Random(a.seed)
    scenes = [(n, tomllib.load(open(os.path.join(base, n), "rb")))
              for n in sorted(os.listdir(base)) if n.endswith(".toml")]
    flagged = rendered = 0
    for i in range(a.runs):
        if a.mode == "scenes":
            name, scene = rng.choice(scenes)
            target = "fuzzed.toml"
            open(os.path.join(runs, target), "w").write(toml_text(mutate_scene(rng, scene)))
            cmd = ["render", target]
        else:
            target, cmd = rng.choice(FILE_TARGETS)
            name = target
            original = open(os.path.join(base, target), "rb").read()
            open(os.path.join(runs, target), "wb").write(corrupt_bytes(rng, original))
        if cmd[0] == "render":
            cmd = cmd + ["--spp", "1", "--res", "8x6", "--threads", "1", "-q", "-o", "out"]
        for f in OUTPUTS:
            if os.path.exists(os.path.join(runs, f)):
                os.remove(os.path.join(runs, f))
        rc, err = run([striae] + cmd, runs, env, a.timeout)
        rendered += rc == 0
        left = [f for f in OUTPUTS if os.path.exists(os.path.join(runs, f))]
        junk = [f for f in os.listdir(runs) if ".tmp-" in f]
        kind = None
        if rc == "timeout":
            kind = "timeout"
        elif rc == 101 or "panicked" in err or rc < 0:
            kind = "panic"
        elif rc != 0 and target not in err:
            kind = "file-not-named"
        elif rc != 0 and left:
            kind = "output-on-failure"
        elif junk:
            kind = "temporary-file-left"
        if kind:
            flagged += 1
            keep = os.path.join(work, f"bad-{flagged}-{kind}-{target}")
            shutil.copy(os.path.join(runs, target), keep)
            lines = err.strip().splitlines()
            at = next((k for k, line in enumerate(lines) if "panicked at" in line), None)
            tail = " | ".join(lines[at:at + 2] if at is not None else lines[-3:])[:300]
            print(f"[{i}] {kind} ({name}, striae {' '.join(cmd)}): {tail}\n    kept as {keep}", flush=True)
        for f in junk:
            os.remove(os.path.join(runs, f))
        if a.mode == "files":
            shutil.copy(os.path.join(base, target), os.path.join(runs, target))
    print(f"{a.runs} runs ({rendered} succeeded, the rest refused with an error), {flagged} flagged")
    sys.exit(1 if flagged else 0)


if __name__ == "__main__":
    main()
