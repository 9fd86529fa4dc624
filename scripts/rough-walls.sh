#!/bin/sh
# R + T of lossless rough groove walls (glass; F = 1 metal), scattering once per wall hit
# against walking the microsurface (METHOD.md 9.7): docs/fidelity/rough-walls.csv.
# Usage: cargo build --release && scripts/rough-walls.sh > docs/fidelity/rough-walls.csv
set -e
B=./target/release/striae
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
echo "profile,walls,side,roughness,theta_i,phi_i,r_t_single,r_t_walk"
for prof in v:angle=90 round:depth=0.5; do
for walls in dielectric-outside dielectric-inside specular; do
for a in 0.05 0.2 0.5 1.0; do
for t in 0 30 60 85; do
  case $walls in
    dielectric-outside) args="--walls dielectric --side outside"; w=dielectric; side=outside;;
    dielectric-inside) args="--walls dielectric --side inside --beside"; w=dielectric; side=inside;;
    specular) args="--walls specular --fresnel-law none"; w=specular; side=outside;;
  esac
  one() { $B gonio --profile $prof $args --roughness $a --theta-i $t --phi-i 30 --paths 50000 --bins 8 $1 -o "$TMP/r.npz" 2>&1 | python3 -c "
import sys,re
s=sys.stdin.read()
r=float(re.search(r'albedo_r ([0-9.e-]+)',s).group(1)); t=float(re.search(r'albedo_t ([0-9.e-]+)',s).group(1))
m=re.search(r'intercept ([0-9.e-]+)',s)
k=float(m.group(1)) if m else 1.0
print(f'{(r+t)/k:.5f}')"; }
  echo "$prof,$w,$side,$a,$t,30,$(one --single-scatter),$(one)"
done; done; done; done
