#!/usr/bin/env python3
"""Summarise docs/fidelity/fidelity.csv (written by `striae fidelity`) as Markdown tables.

Usage: python3 validation/fidelity_summary.py [docs/fidelity/fidelity.csv]
"""
import sys

import numpy as np

path = sys.argv[1] if len(sys.argv) > 1 else "docs/fidelity/fidelity.csv"
d = np.genfromtxt(path, delimiter=",", names=True, dtype=None, encoding="utf-8")
models = list(dict.fromkeys(d["model"]))
profiles = list(dict.fromkeys(d["profile"]))

print("| model | median L1 | worst L1 (profile, theta_i, phi_i) | median L1/noise "
      "| worst abs albedo error (profile, theta_i, phi_i) |")
print("|---|---|---|---|---|")
for m in models:
    r = d[d["model"] == m]
    w = np.argmax(r["l1"])
    a = np.argmax(np.abs(r["albedo_err"]))
    print(f"| {m} | {np.median(r['l1']):.4f} | {r['l1'][w]:.4f} ({r['profile'][w]}, "
          f"{r['theta_i'][w]:g}, {r['phi_i'][w]:g}) | {np.median(r['l1_over_noise']):.1f} | "
          f"{r['albedo_err'][a]:+.4f} of {r['albedo_exact'][a]:.4f} ({r['profile'][a]}, "
          f"{r['theta_i'][a]:g}, {r['phi_i'][a]:g}) |")

thetas = sorted(set(d["theta_i"]))
print()
print("Mean L1 over phi_i, per profile and theta_i (noise L1 in brackets):")
print()
print("| profile | model | " + " | ".join(f"{t:g}" for t in thetas) + " |")
print("|---|---|" + "---|" * len(thetas))
for p in profiles:
    for m in models:
        r = d[(d["model"] == m) & (d["profile"] == p)]
        cells = []
        for t in thetas:
            s = r[r["theta_i"] == t]
            cells.append(f"{s['l1'].mean():.4f} ({s['noise_l1'].mean():.4f})")
        print(f"| {p} | {m} | " + " | ".join(cells) + " |")
