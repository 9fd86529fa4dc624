"""Compare the scratch lobes of two groove profiles with striae's Python API.

Precomputes two small tables (a 60-degree V groove and a round one; diffuse walls, no Fresnel
factor), then plots, for light
arriving at phi_i = 30 degrees across the scratch, the lobe of each in the scratch's cross-
section plane (theta = 0: `table.eval` over outgoing angles phi_o), and the directions
`table.sample` draws for that light. Writes compare_profiles.png (or the path given).

    pip install . matplotlib
    python examples/compare_profiles.py [out.png]
"""

import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import striae  # noqa: E402

PROFILES = ["v:angle=60", "round:depth=0.5"]
PHI_I = np.radians(30.0)


def directions(phi, theta=0.0):
    """Scratch-frame unit vectors: phi = atan2(x, z) across the scratch, theta = asin(y)."""
    phi = np.asarray(phi, dtype=float)
    c = np.cos(theta)
    return np.stack([c * np.sin(phi), np.full_like(phi, np.sin(theta)), c * np.cos(phi)], axis=1)


def main(out):
    fig, (lobe, hist) = plt.subplots(1, 2, figsize=(11, 4.2))
    phi_o = np.linspace(-np.pi / 2 + 1e-3, np.pi / 2 - 1e-3, 721)
    rng = np.random.default_rng(1)
    for spec in PROFILES:
        table = striae.precompute(profile=spec, m=128, n=4000, nr=20, seed=1, fresnel_law="none")
        wi = np.repeat(directions([PHI_I]), len(phi_o), axis=0)
        f, _ = table.eval(directions(phi_o), wi)
        lobe.plot(np.degrees(phi_o), f * np.cos(phi_o), label=spec)
        wo = np.repeat(directions([PHI_I]), 200_000, axis=0)
        s_wi, weight, _, valid = table.sample(wo, rng.random((len(wo), 2)))
        phi_s = np.degrees(np.arctan2(s_wi[valid, 0], s_wi[valid, 2]))
        hist.hist(phi_s, bins=90, range=(-90, 90), density=True, histtype="step", label=spec)
        print(f"{spec}: directional albedo at 30 deg = {weight.mean():.4f}")
    lobe.set(xlabel="phi_o (degrees)", ylabel="f cos(phi_o), theta = 0",
             title="scratch lobe for phi_i = 30 deg (table.eval)")
    hist.set(xlabel="sampled phi (degrees)", ylabel="density",
             title="directions drawn by table.sample")
    for ax in (lobe, hist):
        ax.axvline(-30, color="grey", lw=0.8, ls=":", label="mirror direction")
        ax.legend()
    fig.tight_layout()
    fig.savefig(out, dpi=90)
    print(f"wrote {out}")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "compare_profiles.png")
