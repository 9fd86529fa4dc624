//! Scratches with a direction each (`orientation = "random"`, beyond the seed: METHOD.md
//! section 8.4 needs randomly oriented scratches for its halos).
//!
//! The seed's layer (section 5) stretches the whole noise along one direction, so every scratch
//! of a layer runs the same way. Here the feature points of a layer's Worley noise sit on an
//! unstretched grid of cell side `s = sqrt(L W)` in texture space (the same density of
//! scratches, `1 / (L W)` per unit area, as the seed's layer), and the scratch of the feature
//! point of cell `(i, j)` is the ellipse of half-axes `tau L` along its own direction
//! `beta(i, j)` and `tau W` across it, `beta` uniform in `[0, 2 pi)` and hashed from the cell
//! and the layer's seed like the point's position. In noise units (`q = (p - c) / s`) the
//! half-axes are `a = tau sqrt(L / W)` and `b = tau sqrt(W / L)`.
//!
//! Scratches of one layer now cross, so a footprint's coverage is the area of a union of
//! ellipses of different directions clipped to the footprint: [`union_ellipses_area`] computes it
//! exactly by Green's theorem (each ellipse's boundary arcs outside the others and inside the
//! footprint, the footprint's edge pieces inside some ellipse; the crossings of two ellipses are
//! the real roots of a quartic). Where no two candidate ellipses can meet (their bounding boxes
//! are apart, the common case) the areas are summed one by one in closed form, each in the frame
//! that makes its ellipse a unit disc ([`super::layer::disc_parallelogram_area`]).

use super::footprint::MAX_DISCS;
use super::layer::{disc_parallelogram_area, Parallelogram, CENTRE};
use super::worley::{floor_i64, Worley};
use super::{LayerError, LayerParams, Scratch, LAYER_NOISE_PERIOD};
use crate::hash::mix64;
use arrayvec::ArrayVec;
use glam::DVec2;
use std::f64::consts::{PI, TAU};

/// Most cells a point query visits (scratches longer than about 30 cells are not found).
const NEAR_CELLS: usize = 4096;

#[inline]
fn cross(a: DVec2, b: DVec2) -> f64 {
    a.x * b.y - a.y * b.x
}

/// One scratch in noise space: the ellipse `{c + u d a' + v d_perp b' : u^2 + v^2 < 1}`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ellipse {
    /// Centre.
    pub c: DVec2,
    /// Unit direction of the long axis (the scratch direction), `(cos beta, sin beta)`.
    pub d: DVec2,
    /// Half-axes along `d` and across it.
    pub a: f64,
    pub b: f64,
}

impl Ellipse {
    /// `v` in the frame where the ellipse is the unit disc (`T v`, `det T = 1 / (a b)`).
    #[inline]
    pub fn unit(&self, v: DVec2) -> DVec2 {
        DVec2::new(self.d.dot(v) / self.a, cross(self.d, v) / self.b)
    }

    /// `|T (x - c)|^2`: below 1 inside.
    #[inline]
    pub fn norm2(&self, x: DVec2) -> f64 {
        self.unit(x - self.c).length_squared()
    }

    /// The boundary point at parameter `t` relative to the centre (counter-clockwise).
    #[inline]
    fn rim(&self, t: f64) -> DVec2 {
        let (s, c) = t.sin_cos();
        self.d * (self.a * c) + self.d.perp() * (self.b * s)
    }

    /// Whether the bounding boxes (oriented) of two ellipses overlap (separating axes).
    fn boxes_overlap(&self, o: &Ellipse) -> bool {
        let v = o.c - self.c;
        let reach = |e: &Ellipse, n: DVec2| e.a * e.d.dot(n).abs() + e.b * cross(e.d, n).abs();
        [self.d, self.d.perp(), o.d, o.d.perp()]
            .iter()
            .all(|&n| v.dot(n).abs() < reach(self, n) + reach(o, n))
    }
}

/// A layer's randomly oriented scratches (see the module notes).
#[derive(Clone, Debug)]
pub struct RandomScratches {
    noise: Worley,
    dir_key: u64,
    /// Cell side `s = sqrt(L W)` in texture units.
    scale: f64,
    a: f64,
    b: f64,
}

impl RandomScratches {
    /// The scratches of a layer with noise seed `noise_seed` (parameters already valid).
    pub fn new(noise_seed: u64, params: &LayerParams) -> Result<Self, LayerError> {
        let (l, w, tau) = (params.length, params.width, params.threshold);
        Ok(RandomScratches {
            noise: Worley::new(noise_seed, LAYER_NOISE_PERIOD)?,
            dir_key: mix64(noise_seed ^ 0x0d12_ec71_0a5e_ed01),
            scale: (l * w).sqrt(),
            a: tau * (l / w).sqrt(),
            b: tau * (w / l).sqrt(),
        })
    }

    /// The direction `beta` of the scratch of cell `(i, j)`, uniform in `[0, 2 pi)`.
    #[inline]
    pub fn angle(&self, i: i64, j: i64) -> f64 {
        let m = LAYER_NOISE_PERIOD as i64 - 1;
        let h = mix64(((i & m) as u64 | (((j & m) as u64) << 32)) ^ self.dir_key);
        (h >> 11) as f64 * (1.0 / (1u64 << 53) as f64) * TAU
    }

    /// The scratch of cell `(i, j)`, its centre relative to `origin` (noise space).
    #[inline]
    pub fn ellipse(&self, i: i64, j: i64, origin: DVec2) -> Ellipse {
        let o = self.noise.offset(i, j);
        let (s, c) = self.angle(i, j).sin_cos();
        Ellipse {
            c: DVec2::new((i as f64 - origin.x) + o.x, (j as f64 - origin.y) + o.y),
            d: DVec2::new(c, s),
            a: self.a,
            b: self.b,
        }
    }

    /// Texture point to noise space, `q = (p - c) / s`.
    #[inline]
    pub fn to_noise(&self, p: DVec2) -> DVec2 {
        (p - CENTRE) / self.scale
    }

    /// The cells whose scratch may reach the box `q0 +- ext` (noise space), or `None` where
    /// they are more than `max_cells` (or the box is not finite).
    fn cells(&self, q0: DVec2, ext: DVec2, max_cells: usize) -> Option<[i64; 4]> {
        let e = ext + DVec2::splat(self.a);
        if !(q0.is_finite() && e.x < 1e12 && e.y < 1e12 && q0.abs().max_element() < 1e15) {
            return None;
        }
        let (i0, i1) = (floor_i64(q0.x - e.x), floor_i64(q0.x + e.x));
        let (j0, j1) = (floor_i64(q0.y - e.y), floor_i64(q0.y + e.y));
        let cells = (i1 - i0 + 1) as f64 * (j1 - j0 + 1) as f64;
        (cells <= max_cells as f64).then_some([i0, i1, j0, j1])
    }

    /// The scratch nearest to texture point `p` in its own metric (`|T (q - c)|`, below 1
    /// inside): its normalised distance and direction `beta`; `None` where no scratch reaches
    /// `p` (nor could: nothing within `a` cells).
    pub fn nearest(&self, p: DVec2) -> Option<(f64, f64)> {
        self.nearest_cell(p)
            .map(|(n2, i, j, _)| (n2.sqrt(), self.angle(i, j)))
    }

    /// The scratch nearest to texture point `p` in its own metric as a texture-space
    /// [`Scratch`] of layer `layer`.
    pub fn nearest_scratch(&self, p: DVec2, layer: usize) -> Option<Scratch> {
        self.nearest_cell(p).map(|(_, _, _, e)| Scratch {
            layer,
            centre: p + e.c * self.scale,
            direction: e.d,
            half_length: e.a * self.scale,
            half_width: e.b * self.scale,
        })
    }

    /// The nearest scratch's `|T (q - c)|^2`, cell and ellipse, centred relative to `p`
    /// (noise space).
    fn nearest_cell(&self, p: DVec2) -> Option<(f64, i64, i64, Ellipse)> {
        let q = self.to_noise(p);
        let [i0, i1, j0, j1] = self.cells(q, DVec2::ZERO, NEAR_CELLS)?;
        let mut best: Option<(f64, i64, i64)> = None;
        for j in j0..=j1 {
            for i in i0..=i1 {
                let n2 = self.ellipse(i, j, q).norm2(DVec2::ZERO);
                if best.is_none_or(|b| n2 < b.0) {
                    best = Some((n2, i, j));
                }
            }
        }
        best.map(|(n2, i, j)| (n2, i, j, self.ellipse(i, j, q)))
    }

    /// The mean coverage over the noise, the value for footprints too large to enumerate:
    /// estimated from 2^18 point tests on a 256 x 256 grid of cells (one hashed point per
    /// sub-cell, relative standard error about 1 % at the seed's coverages).
    pub fn expected_coverage(&self) -> f64 {
        const SIDE: u64 = 256;
        let mut hits = 0u64;
        for k in 0..SIDE * SIDE {
            let h = mix64(k ^ 0x3c0e_7a6e_0000_0001);
            let jitter = DVec2::new((h >> 40) as f64, (h & 0xff_ffff) as f64) / (1u64 << 24) as f64;
            let cell = DVec2::new((k % SIDE) as f64, (k / SIDE) as f64);
            // Four points a cell, one in each quarter.
            for (x, y) in [(0.0, 0.0), (0.5, 0.0), (0.0, 0.5), (0.5, 0.5)] {
                let q = cell + DVec2::new(x, y) + jitter * 0.5;
                hits += self.scratched_at_noise(q) as u64;
            }
        }
        hits as f64 / (4 * SIDE * SIDE) as f64
    }

    /// Whether noise point `q` lies in a scratch.
    fn scratched_at_noise(&self, q: DVec2) -> bool {
        let Some([i0, i1, j0, j1]) = self.cells(q, DVec2::ZERO, NEAR_CELLS) else {
            return false;
        };
        (j0..=j1).any(|j| (i0..=i1).any(|i| self.ellipse(i, j, q).norm2(DVec2::ZERO) < 1.0))
    }

    /// Whether texture point `p` is scratched.
    pub fn is_scratched(&self, p: DVec2) -> bool {
        self.scratched_at_noise(self.to_noise(p))
    }

    /// The exact coverage of the footprint `{p + s ea + t eb : s, t in [-1/2, 1/2]}` (texture
    /// space), or `None` where it spans more than `max_cells` cells or meets more than
    /// [`MAX_DISCS`] scratches. A degenerate footprint is a point query; non-finite input gives 0.
    pub fn coverage(&self, p: DVec2, ea: DVec2, eb: DVec2, max_cells: usize) -> Option<f64> {
        let q0 = self.to_noise(p);
        let (qa, qb) = (ea / self.scale, eb / self.scale);
        let cr = cross(qa, qb);
        if !(q0.is_finite() && cr.is_finite()) {
            return Some(0.0);
        }
        if cr.abs() < 1e-12 {
            return Some(self.is_scratched(p) as u8 as f64);
        }
        let (qa, qb) = if cr > 0.0 { (qa, qb) } else { (qb, qa) };
        let ext = (qa.abs() + qb.abs()) * 0.5;
        let [i0, i1, j0, j1] = self.cells(q0, ext, max_cells)?;
        let shape = Parallelogram::new(qa, qb);
        let mut found: ArrayVec<(Ellipse, f64), MAX_DISCS> = ArrayVec::new();
        for j in j0..=j1 {
            for i in i0..=i1 {
                let e = self.ellipse(i, j, q0);
                // The ellipse lies within `a` of its centre: far from a slab, it misses.
                if shape.planes[..2]
                    .iter()
                    .any(|&(n, h)| n.dot(e.c).abs() - h >= self.a)
                {
                    continue;
                }
                let unit = Parallelogram::new(e.unit(qa), e.unit(qb));
                let area = disc_parallelogram_area(e.unit(-e.c), 1.0, &unit) * self.a * self.b;
                if area > 0.0 && found.try_push((e, area)).is_err() {
                    return None;
                }
            }
        }
        let overlap = found
            .iter()
            .enumerate()
            .any(|(k, x)| found[k + 1..].iter().any(|y| x.0.boxes_overlap(&y.0)));
        let area = if overlap {
            let ellipses: ArrayVec<Ellipse, MAX_DISCS> = found.iter().map(|x| x.0).collect();
            union_ellipses_area(&ellipses, &shape.poly)
        } else {
            found.iter().map(|x| x.1).sum()
        };
        let c = area / cr.abs();
        Some(if c < 1e-12 { 0.0 } else { c.min(1.0) })
    }
}

/// Intervals of a circle's parameter, merged.
type Intervals = ArrayVec<(f64, f64), { 4 * MAX_DISCS + 16 }>;

/// Push the cyclic interval `[t0, t1]` (`t1 >= t0`, length below `2 pi`) of `[-pi, pi)`,
/// split where it wraps.
fn push_cyclic(iv: &mut Intervals, t0: f64, t1: f64) {
    let len = (t1 - t0).max(0.0);
    let t0 = (t0 + PI).rem_euclid(TAU) - PI;
    let t1 = t0 + len;
    if t1 <= PI {
        iv.push((t0, t1));
    } else {
        iv.push((t0, PI));
        iv.push((-PI, t1 - TAU));
    }
}

/// The real roots of the polynomial `c[0] + c[1] x + ... + c[n] x^n` (degree at most 4),
/// isolated between the roots of its derivative and refined by bisection.
fn real_roots(c: &[f64]) -> ArrayVec<f64, 4> {
    let scale = c.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let mut n = c.len() - 1;
    while n > 0 && c[n].abs() <= 1e-13 * scale {
        n -= 1;
    }
    let c = &c[..=n];
    let mut out = ArrayVec::new();
    if n == 0 {
        return out;
    }
    if n == 1 {
        out.push(-c[0] / c[1]);
        return out;
    }
    let deriv: ArrayVec<f64, 4> = (1..=n).map(|k| c[k] * k as f64).collect();
    let crit = real_roots(&deriv);
    // Cauchy's bound holds every root.
    let bound = 1.0 + c[..n].iter().fold(0.0f64, |m, x| m.max((x / c[n]).abs()));
    let eval = |x: f64| c.iter().rev().fold(0.0, |acc, &k| acc * x + k);
    let mut edges: ArrayVec<f64, 6> = ArrayVec::new();
    edges.push(-bound);
    for x in crit {
        if x > -bound && x < bound {
            edges.push(x);
        }
    }
    edges.push(bound);
    edges.sort_unstable_by(f64::total_cmp);
    for w in edges.windows(2) {
        let (mut lo, mut hi) = (w[0], w[1]);
        let (flo, fhi) = (eval(lo), eval(hi));
        if flo == 0.0 {
            if !out.contains(&lo) {
                out.push(lo);
            }
            continue;
        }
        if flo.signum() == fhi.signum() {
            continue;
        }
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if mid <= lo || mid >= hi {
                break;
            }
            if eval(mid).signum() == flo.signum() {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        if out.len() < 4 {
            out.push(0.5 * (lo + hi));
        }
    }
    out
}

/// The parameters `t` in `[-pi, pi)` of `e`'s boundary that lie inside `o`, as intervals.
fn inside_other(e: &Ellipse, o: &Ellipse, iv: &mut Intervals) {
    // |g + U cos t + V sin t|^2 - 1 in o's unit frame, with x = tan(t / 2).
    let g = o.unit(e.c - o.c);
    let u = o.unit(e.d * e.a);
    let v = o.unit(e.d.perp() * e.b);
    let c0 = g.length_squared() - 1.0;
    let (gu, gv, uu, vv, uv) = (g.dot(u), g.dot(v), u.dot(u), v.dot(v), u.dot(v));
    let poly = [
        c0 + 2.0 * gu + uu,
        4.0 * gv + 4.0 * uv,
        2.0 * c0 - 2.0 * uu + 4.0 * vv,
        4.0 * gv - 4.0 * uv,
        c0 - 2.0 * gu + uu,
    ];
    let mut ts: ArrayVec<f64, 6> = real_roots(&poly).iter().map(|&x| 2.0 * x.atan()).collect();
    ts.push(-PI);
    ts.push(PI);
    ts.sort_unstable_by(f64::total_cmp);
    for w in ts.windows(2) {
        if w[1] > w[0] && o.norm2(e.c + e.rim(0.5 * (w[0] + w[1]))) < 1.0 {
            iv.push((w[0], w[1]));
        }
    }
}

/// Sort and merge intervals in place.
fn merge(iv: &mut Intervals) {
    iv.sort_unstable_by(|x, y| x.0.total_cmp(&y.0));
    let mut n = 0;
    for k in 0..iv.len() {
        if n > 0 && iv[k].0 <= iv[n - 1].1 {
            iv[n - 1].1 = iv[n - 1].1.max(iv[k].1);
        } else {
            iv[n] = iv[k];
            n += 1;
        }
    }
    iv.truncate(n);
}

/// Area of `(union of ellipses) ∩ polygon` (convex, counter-clockwise, at most 8 edges), by
/// Green's theorem, `A = 1/2 ∮ (x dy - y dx)` over the boundary (see the module notes). An arc
/// `[t0, t1]` of ellipse `(c, d, a, b)` adds `a b (t1 - t0) + cross(c, rim(t1) - rim(t0))`; an
/// edge piece from `x0` to `x1` adds `cross(x0, x1)`.
pub fn union_ellipses_area(ellipses: &[Ellipse], poly: &[DVec2]) -> f64 {
    let ne = poly.len();
    let mut twice = 0.0;
    'arcs: for (k, e) in ellipses.iter().enumerate() {
        let mut iv = Intervals::new();
        for i in 0..ne {
            let (p, q) = (poly[i], poly[(i + 1) % ne]);
            let n = (q - p).perp().normalize() * -1.0; // outward (counter-clockwise polygon)
            let r = n.dot(p) - n.dot(e.c);
            let (pc, ps) = (n.dot(e.d) * e.a, n.dot(e.d.perp()) * e.b);
            let m = pc.hypot(ps);
            if r >= m {
                continue;
            }
            if r <= -m {
                continue 'arcs; // wholly outside this edge
            }
            let (phi, w) = (ps.atan2(pc), (r / m).acos());
            push_cyclic(&mut iv, phi - w, phi + w);
        }
        for (j, o) in ellipses.iter().enumerate() {
            if j != k && e.boxes_overlap(o) {
                inside_other(e, o, &mut iv);
            }
        }
        merge(&mut iv);
        let mut t = -PI;
        let arc = |t0: f64, t1: f64| e.a * e.b * (t1 - t0) + cross(e.c, e.rim(t1) - e.rim(t0));
        for &(t0, t1) in iv.iter() {
            if t0 > t {
                twice += arc(t, t0);
            }
            t = t.max(t1);
        }
        if t < PI {
            twice += arc(t, PI);
        }
    }
    for i in 0..ne {
        let (p, q) = (poly[i], poly[(i + 1) % ne]);
        let dv = q - p;
        let mut iv = Intervals::new();
        for o in ellipses {
            // |T (p - c) + s T dv|^2 < 1 for s in [0, 1].
            let (y, z) = (o.unit(p - o.c), o.unit(dv));
            let (qa, qb, qc) = (z.dot(z), 2.0 * y.dot(z), y.dot(y) - 1.0);
            let disc = qb * qb - 4.0 * qa * qc;
            if qa <= 0.0 || disc <= 0.0 {
                continue;
            }
            let sq = disc.sqrt();
            let (s0, s1) = ((-qb - sq) / (2.0 * qa), (-qb + sq) / (2.0 * qa));
            let (s0, s1) = (s0.max(0.0), s1.min(1.0));
            if s1 > s0 {
                iv.push((s0, s1));
            }
        }
        merge(&mut iv);
        for &(s0, s1) in iv.iter() {
            twice += cross(p + dv * s0, p + dv * s1);
        }
    }
    (0.5 * twice).max(0.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::chi2_discrete;
    use rand::{Rng, SeedableRng};

    fn params() -> LayerParams {
        LayerParams {
            length: 0.3,
            width: 0.01,
            threshold: 0.1,
            layers: 1,
        }
    }

    /// The directions of a layer's scratches are uniform on the circle: chi-square over 36
    /// sectors of 20 000 cells.
    #[test]
    fn directions_are_uniform() {
        let r = RandomScratches::new(5, &params()).unwrap();
        let mut counts = vec![0u64; 36];
        let n = 20_000i64;
        for k in 0..n {
            let beta = r.angle(k % 200 - 100, k / 200 - 50);
            assert!((0.0..TAU).contains(&beta));
            counts[((beta / TAU * 36.0) as usize).min(35)] += 1;
        }
        let res = chi2_discrete(&counts, &vec![n as f64 / 36.0; 36]);
        assert!(res.p_value > 1e-3, "directions not uniform: {res:?}");
        // Not all alike: another seed gives other directions.
        let other = RandomScratches::new(6, &params()).unwrap();
        assert_ne!(r.angle(3, 4), other.angle(3, 4));
    }

    /// The share of an `n x n` grid of cell centres `(s, t)` in `[-1/2, 1/2]^2` where `inside`.
    fn grid_share(n: usize, inside: impl Fn(f64, f64) -> bool) -> f64 {
        let c = |k: usize| (k as f64 + 0.5) / n as f64 - 0.5;
        let hits = (0..n * n).filter(|&k| inside(c(k % n), c(k / n))).count();
        hits as f64 / (n * n) as f64
    }

    /// The union area against a fine grid of point tests, for crossing ellipses clipped to a
    /// parallelogram (a reference the area code does not share).
    #[test]
    fn union_area_matches_point_sampling() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(3);
        for case in 0..12 {
            let ellipses: Vec<Ellipse> = (0..2 + case % 4)
                .map(|_| {
                    let beta: f64 = rng.random_range(0.0..TAU);
                    Ellipse {
                        c: DVec2::new(rng.random_range(-0.6..0.6), rng.random_range(-0.6..0.6)),
                        d: DVec2::new(beta.cos(), beta.sin()),
                        a: rng.random_range(0.3..1.2),
                        b: rng.random_range(0.02..0.3),
                    }
                })
                .collect();
            let qa = DVec2::new(1.3, 0.2);
            let qb = DVec2::new(-0.3, 1.1);
            let shape = Parallelogram::new(qa, qb);
            let exact = union_ellipses_area(&ellipses, &shape.poly);
            let sampled = grid_share(1000, |s, t| {
                let pt = qa * s + qb * t;
                ellipses.iter().any(|e| e.norm2(pt) < 1.0)
            }) * shape.area;
            assert!(
                (exact - sampled).abs() < 2e-3 * shape.area,
                "case {case}: exact {exact} sampled {sampled}"
            );
        }
    }

    /// A footprint's coverage against point sampling over it, crossings included.
    #[test]
    fn coverage_matches_point_sampling() {
        let r = RandomScratches::new(9, &params()).unwrap();
        let mut rng = rand_pcg::Pcg64::seed_from_u64(4);
        for _ in 0..20 {
            let p = DVec2::new(rng.random_range(0.0..1.0), rng.random_range(0.0..1.0));
            let ea = DVec2::new(0.05, 0.01);
            let eb = DVec2::new(-0.01, 0.04);
            let c = r.coverage(p, ea, eb, 4096).unwrap();
            let sampled = grid_share(400, |s, t| r.is_scratched(p + ea * s + eb * t));
            assert!(
                (c - sampled).abs() < 4e-3,
                "at {p:?}: exact {c} sampled {sampled}"
            );
        }
    }

    #[test]
    fn quartic_roots() {
        // (x - 1)(x + 2)(x - 0.5)(x + 3) = x^4 + 3.5 x^3 - x^2 - 6.5 x + 3
        let mut r = real_roots(&[3.0, -6.5, -1.0, 3.5, 1.0]);
        r.sort_unstable_by(f64::total_cmp);
        let want = [-3.0, -2.0, 0.5, 1.0];
        assert_eq!(r.len(), 4);
        for (a, b) in r.iter().zip(want) {
            assert!((a - b).abs() < 1e-12, "{r:?}");
        }
        assert!(real_roots(&[1.0, 0.0, 1.0]).is_empty());
    }
}
