#!/usr/bin/env python3
"""striae's conductor presets against Mitsuba 3's built-in `conductor` materials.

striae's presets (`crates/striae/src/material.rs`, `CONDUCTOR_PRESETS`, copied into
`scripts/mitsuba_scene.py` as `PRESETS` for the scene translation) give each metal's complex
IOR in linear RGB. Mitsuba's `conductor` plugin computes its own RGB values from spectral data
when given `material = "Au"` etc. This script compares the two: the Fresnel reflectance each
gives at 0, 60 and 80 degrees, as Mitsuba's `conductor` evaluates it. It stops with an error if
any channel differs by more than `--tol`.

    pip install mitsuba numpy
    python3 validation/check_presets.py [--tol 1e-3]
"""
import argparse
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "scripts"))
import mitsuba_scene  # noqa: E402  (PRESETS)

# Mitsuba's name for each of striae's presets that it also has.
MITSUBA_NAMES = {"au": "Au", "ag": "Ag", "cu": "Cu", "al": "Al", "cr": "Cr"}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--tol", type=float, default=1e-3)
    a = ap.parse_args()
    import mitsuba as mi
    mi.set_variant("scalar_rgb")
    worst = 0.0
    print(f"{'preset':8s} {'angle':>5s}  {'Mitsuba built-in (R, G, B)':28s} {'striae preset (R, G, B)':28s}")
    for names, (eta, k) in mitsuba_scene.PRESETS.items():
        if names[0] not in MITSUBA_NAMES:
            continue
        builtin = mi.load_dict({"type": "conductor", "material": MITSUBA_NAMES[names[0]]})
        ours = mi.load_dict({"type": "conductor", "eta": {"type": "rgb", "value": eta},
                             "k": {"type": "rgb", "value": k}})
        for deg in (0, 60, 80):
            t = np.radians(deg)
            si = mi.SurfaceInteraction3f()
            si.wi = mi.Vector3f(np.sin(t), 0.0, np.cos(t))
            ctx = mi.BSDFContext()
            rb = np.array(builtin.sample(ctx, si, 0.5, [0.5, 0.5])[1])
            ro = np.array(ours.sample(ctx, si, 0.5, [0.5, 0.5])[1])
            worst = max(worst, float(np.abs(rb - ro).max()))
            print(f"{names[1]:8s} {deg:5d}  {np.array2string(rb, precision=4):28s} "
                  f"{np.array2string(ro, precision=4):28s}")
    print(f"largest difference: {worst:.2e}")
    if worst > a.tol:
        sys.exit(f"a preset differs from Mitsuba's by {worst:.2e} > {a.tol}")


if __name__ == "__main__":
    main()
