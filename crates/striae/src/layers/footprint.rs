//! Exact area of a union of equal discs clipped to a convex polygon, the geometric kernel of
//! the footprint queries and of the anti-aliased rasteriser (METHOD.md section 5: in noise
//! space every scratch is a disc of radius tau around a feature point, and the affine map from
//! texture space preserves area ratios, so a footprint's scratch coverage is
//! `area(union of discs ∩ footprint) / area(footprint)` computed in noise space).
//!
//! The area comes from Green's theorem, `A = 1/2 ∮ (x dy - y dx)`, over the boundary of
//! `(∪ discs) ∩ polygon`: the arcs of each circle that lie inside the polygon and outside every
//! other disc, and the pieces of each polygon edge that lie inside some disc. Both are unions of
//! intervals (in angle, in edge parameter), so the result is exact up to rounding, overlaps and
//! all. Also here: the expected coverage of the whole noise (the mean over the hash), used as the
//! prefiltered value of footprints too large to enumerate.

use glam::DVec2;

/// At most this many discs take part in one exact evaluation (callers fall back beyond it).
pub const MAX_DISCS: usize = 64;
/// At most this many polygon edges.
pub const MAX_EDGES: usize = 8;

const TAU: f64 = std::f64::consts::TAU;

#[inline]
fn cross(a: DVec2, b: DVec2) -> f64 {
    a.x * b.y - a.y * b.x
}

/// Sort intervals by start and return the merged union (in place, returns the count).
fn merge(iv: &mut [(f64, f64)]) -> usize {
    if iv.len() <= 1 {
        return iv.len();
    }
    iv.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    let mut n = 0;
    for k in 1..iv.len() {
        if iv[k].0 <= iv[n].1 {
            iv[n].1 = iv[n].1.max(iv[k].1);
        } else {
            n += 1;
            iv[n] = iv[k];
        }
    }
    n + 1
}

/// A monotone stand-in for the angle of a unit vector, in `[0, 4)` counter-clockwise from +x.
#[inline]
fn pseudo_angle(v: DVec2) -> f64 {
    let p = v.x / (v.x.abs() + v.y.abs());
    if v.y >= 0.0 {
        1.0 - p
    } else {
        3.0 + p
    }
}

/// An angular interval on a circle: pseudo-angles `k0 <= k1` and the unit vectors at its ends.
#[derive(Clone, Copy)]
struct Arc {
    k0: f64,
    k1: f64,
    e0: DVec2,
    e1: DVec2,
}

impl Arc {
    const EMPTY: Arc = Arc {
        k0: 0.0,
        k1: 0.0,
        e0: DVec2::X,
        e1: DVec2::X,
    };

    /// Push the arc of directions within `beta = acos(cos_beta)` of unit vector `m`, split at +x.
    #[inline]
    fn push_excluded(iv: &mut [Arc], n: &mut usize, m: DVec2, cos_beta: f64) {
        let sin_beta = (1.0 - cos_beta * cos_beta).max(0.0).sqrt();
        let e0 = DVec2::new(
            m.x * cos_beta + m.y * sin_beta,
            m.y * cos_beta - m.x * sin_beta,
        );
        let e1 = DVec2::new(
            m.x * cos_beta - m.y * sin_beta,
            m.y * cos_beta + m.x * sin_beta,
        );
        let (k0, k1) = (pseudo_angle(e0), pseudo_angle(e1));
        if k0 <= k1 {
            iv[*n] = Arc { k0, k1, e0, e1 };
            *n += 1;
        } else {
            // Wraps through +x.
            iv[*n] = Arc {
                k0,
                k1: 4.0,
                e0,
                e1: DVec2::X,
            };
            iv[*n + 1] = Arc {
                k0: 0.0,
                k1,
                e0: DVec2::X,
                e1,
            };
            *n += 2;
        }
    }

    /// Sort by start and merge overlapping arcs in place; returns the count.
    fn merge(iv: &mut [Arc]) -> usize {
        iv.sort_unstable_by(|a, b| a.k0.total_cmp(&b.k0));
        let mut n = 0;
        for k in 1..iv.len() {
            if iv[k].k0 <= iv[n].k1 {
                if iv[k].k1 > iv[n].k1 {
                    iv[n].k1 = iv[k].k1;
                    iv[n].e1 = iv[k].e1;
                }
            } else {
                n += 1;
                iv[n] = iv[k];
            }
        }
        n + 1
    }
}

/// Area of `(∪_k disc(centres[k], r)) ∩ polygon` for a convex polygon given counter-clockwise.
/// Exact (Green's theorem over arcs and edge pieces). Coordinates should be small (put the
/// origin near the polygon) for best rounding. At most [`MAX_DISCS`] discs and [`MAX_EDGES`]
/// edges.
pub fn union_discs_polygon_area(centres: &[DVec2], r: f64, poly: &[DVec2]) -> f64 {
    let (nd, ne) = (centres.len(), poly.len());
    assert!(nd <= MAX_DISCS && (3..=MAX_EDGES).contains(&ne));
    if nd == 0 || r <= 0.0 {
        return 0.0;
    }
    // Scratch arrays sized for the case at hand (zeroing the largest ones would dominate the
    // single-disc case of the rasteriser).
    match nd {
        1 => union_area::<{ 2 * MAX_EDGES }, 1>(centres, r, poly),
        2..=8 => union_area::<{ 2 * (MAX_EDGES + 8) }, 8>(centres, r, poly),
        _ => union_area::<{ 2 * (MAX_EDGES + MAX_DISCS) }, MAX_DISCS>(centres, r, poly),
    }
}

/// [`union_discs_polygon_area`] with room for `ARCS` excluded arcs per circle and `DISCS` discs.
fn union_area<const ARCS: usize, const DISCS: usize>(
    centres: &[DVec2],
    r: f64,
    poly: &[DVec2],
) -> f64 {
    let normals = edge_lines(poly);
    let normals = &normals[..poly.len()];
    let mut twice_area = 0.0;
    // Excluded arcs of the circle at hand, reused from circle to circle.
    let mut iv = [Arc::EMPTY; ARCS];
    for (ci, &c) in centres.iter().enumerate() {
        circle_arcs(ci, c, centres, r, normals, &mut iv, &mut twice_area);
    }
    edge_pieces::<DISCS>(centres, r, poly, &mut twice_area);
    (0.5 * twice_area).max(0.0)
}

/// The outward unit normal `n` and offset `d` of each edge's line (inside is `n.x <= d`);
/// zero for a zero-length edge.
#[inline]
fn edge_lines(poly: &[DVec2]) -> [(DVec2, f64); MAX_EDGES] {
    let ne = poly.len();
    let mut normals = [(DVec2::ZERO, 0.0f64); MAX_EDGES];
    for e in 0..ne {
        let (a, b) = (poly[e], poly[(e + 1) % ne]);
        let d = b - a;
        let len = d.length();
        if len == 0.0 {
            normals[e] = (DVec2::ZERO, 0.0);
            continue;
        }
        let n = DVec2::new(d.y, -d.x) / len;
        normals[e] = (n, n.dot(a));
    }
    normals
}

/// Adds to `twice_area` the boundary integral over the arcs of circle `ci` (centre `c`) that
/// lie inside the polygon (edge lines `normals`) and outside every other disc. The excluded
/// angular intervals go to `iv`, kept as unit vectors ordered by a pseudo-angle: no
/// trigonometry but one `atan2` per kept arc.
#[inline]
fn circle_arcs(
    ci: usize,
    c: DVec2,
    centres: &[DVec2],
    r: f64,
    normals: &[(DVec2, f64)],
    iv: &mut [Arc],
    twice_area: &mut f64,
) {
    let r2 = r * r;
    let mut n = 0usize;
    for &(nrm, d) in normals {
        if nrm == DVec2::ZERO {
            continue;
        }
        let s = d - nrm.dot(c); // signed distance of the centre inside the edge's line
        if s >= r {
            continue;
        }
        if s <= -r {
            return; // the whole circle is outside the polygon
        }
        Arc::push_excluded(iv, &mut n, nrm, s / r);
    }
    for (cj, &o) in centres.iter().enumerate() {
        if cj == ci {
            continue;
        }
        let v = o - c;
        let dist = v.length();
        if dist >= 2.0 * r {
            continue;
        }
        if dist == 0.0 {
            // Coincident circles: keep the boundary of the first copy only.
            if cj < ci {
                return;
            }
            continue;
        }
        Arc::push_excluded(iv, &mut n, v / dist, dist / (2.0 * r));
    }
    if n == 0 {
        *twice_area += r2 * TAU; // the whole circle bounds the region
        return;
    }
    let m = Arc::merge(&mut iv[..n]);
    // Integrate (x dy - y dx) = r^2 + r (cx cos t + cy sin t) dt over the kept arcs, from
    // unit vector e0 to e1 counter-clockwise.
    let mut arc = |e0: DVec2, e1: DVec2| {
        let mut dt = cross(e0, e1).atan2(e0.dot(e1));
        if dt < 0.0 {
            dt += TAU;
        }
        *twice_area += r2 * dt + r * (c.x * (e1.y - e0.y) - c.y * (e1.x - e0.x));
    };
    if iv[0].k0 > 0.0 {
        arc(DVec2::X, iv[0].e0);
    }
    for w in 0..m {
        let next = if w + 1 < m {
            iv[w + 1]
        } else {
            Arc {
                k0: 4.0,
                e0: DVec2::X,
                ..Arc::EMPTY
            }
        };
        if next.k0 > iv[w].k1 {
            arc(iv[w].e1, next.e0);
        }
    }
}

/// Adds to `twice_area` the boundary integral over the pieces of each polygon edge inside
/// some disc: `(x dy - y dx)` along `a -> b` is `cross(a, b) dt`.
#[inline]
fn edge_pieces<const DISCS: usize>(
    centres: &[DVec2],
    r: f64,
    poly: &[DVec2],
    twice_area: &mut f64,
) {
    let (ne, r2) = (poly.len(), r * r);
    let mut tv = [(0.0f64, 0.0f64); DISCS];
    for e in 0..ne {
        let (a, b) = (poly[e], poly[(e + 1) % ne]);
        let d = b - a;
        let dd = d.length_squared();
        if dd == 0.0 {
            continue;
        }
        let mut n = 0;
        for &c in centres {
            // |a + t d - c|^2 < r^2
            let w = a - c;
            let half_b = d.dot(w) / dd;
            let disc = half_b * half_b - (w.length_squared() - r2) / dd;
            if disc <= 0.0 {
                continue;
            }
            let s = disc.sqrt();
            let (t0, t1) = ((-half_b - s).max(0.0), (-half_b + s).min(1.0));
            if t1 > t0 {
                tv[n] = (t0, t1);
                n += 1;
            }
        }
        let m = merge(&mut tv[..n]);
        let covered: f64 = tv[..m].iter().map(|(t0, t1)| t1 - t0).sum();
        *twice_area += cross(a, b) * covered;
    }
}

/// The mean coverage of Worley noise thresholded at `tau` (`F1 < tau`), averaged over the hash:
/// with independent uniform feature points, a point `q` is uncovered iff no cell's point lies
/// within `tau`, so `E = mean_q [1 - prod_c (1 - area(disc(q, tau) ∩ cell c))]`. The mean over
/// `q` in the unit cell is a midpoint rule on `n x n` points (smooth integrand; `n = 48` is
/// accurate to about 1e-6). For small tau this is `pi tau^2` less the overlaps of neighbouring
/// scratches (0.2 % at tau = 0.1: a jittered grid overlaps less than Poisson points).
pub fn expected_coverage(tau: f64, n: usize) -> f64 {
    let mut sum = 0.0;
    for y in 0..n {
        for x in 0..n {
            let q = DVec2::new((x as f64 + 0.5) / n as f64, (y as f64 + 0.5) / n as f64);
            let mut uncovered = 1.0;
            for dj in -1..=1 {
                for di in -1..=1 {
                    // Cell (di, dj) relative to q: the unit square with origin at q.
                    let o = DVec2::new(di as f64, dj as f64) - q;
                    let sq = [o, o + DVec2::X, o + DVec2::ONE, o + DVec2::Y];
                    let a = union_discs_polygon_area(&[DVec2::ZERO], tau, &sq);
                    uncovered *= 1.0 - a;
                }
            }
            sum += 1.0 - uncovered;
        }
    }
    sum / (n * n) as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use std::f64::consts::PI;

    /// Reference area by a fine midpoint grid over the polygon's bounding box.
    fn grid_area(centres: &[DVec2], r: f64, poly: &[DVec2], n: usize) -> f64 {
        let lo = poly
            .iter()
            .fold(DVec2::splat(f64::INFINITY), |m, p| m.min(*p));
        let hi = poly
            .iter()
            .fold(DVec2::splat(f64::NEG_INFINITY), |m, p| m.max(*p));
        let cell = (hi - lo) / n as f64;
        let mut count = 0usize;
        for y in 0..n {
            for x in 0..n {
                let p = lo + cell * DVec2::new(x as f64 + 0.5, y as f64 + 0.5);
                let inside_poly = (0..poly.len())
                    .all(|e| cross(poly[(e + 1) % poly.len()] - poly[e], p - poly[e]) >= 0.0);
                if inside_poly && centres.iter().any(|c| (p - *c).length_squared() < r * r) {
                    count += 1;
                }
            }
        }
        count as f64 * cell.x * cell.y
    }

    #[test]
    fn closed_forms() {
        let sq = [
            DVec2::new(-1.0, -1.0),
            DVec2::new(1.0, -1.0),
            DVec2::new(1.0, 1.0),
            DVec2::new(-1.0, 1.0),
        ];
        // A disc inside the square.
        let a = union_discs_polygon_area(&[DVec2::new(0.1, -0.2)], 0.5, &sq);
        assert!((a - PI * 0.25).abs() < 1e-12);
        // The square inside a disc.
        let a = union_discs_polygon_area(&[DVec2::ZERO], 2.0, &sq);
        assert!((a - 4.0).abs() < 1e-12);
        // A disc cut in half by an edge.
        let a = union_discs_polygon_area(&[DVec2::new(1.0, 0.0)], 0.5, &sq);
        assert!((a - PI * 0.125).abs() < 1e-12);
        // A circular segment: disc centre 0.3 outside the edge x = 1, r = 0.5.
        let (r, h) = (0.5f64, 0.2f64); // segment height r - 0.3
        let seg = r * r * ((r - h) / r).acos() - (r - h) * (2.0 * r * h - h * h).sqrt();
        let a = union_discs_polygon_area(&[DVec2::new(1.3, 0.0)], r, &sq);
        assert!((a - seg).abs() < 1e-12, "{a} vs {seg}");
        // Two overlapping discs inside: 2 pi r^2 minus the lens.
        let (r, d) = (0.3f64, 0.2f64);
        let lens = 2.0 * r * r * (d / (2.0 * r)).acos() - 0.5 * d * (4.0 * r * r - d * d).sqrt();
        let a = union_discs_polygon_area(&[DVec2::new(-0.1, 0.0), DVec2::new(0.1, 0.0)], r, &sq);
        assert!((a - (2.0 * PI * r * r - lens)).abs() < 1e-12);
        // A disc far outside, and a duplicate disc counted once.
        assert_eq!(
            union_discs_polygon_area(&[DVec2::new(5.0, 0.0)], 0.5, &sq),
            0.0
        );
        let a = union_discs_polygon_area(&[DVec2::ZERO, DVec2::ZERO], 0.5, &sq);
        assert!((a - PI * 0.25).abs() < 1e-12);
    }

    #[test]
    fn random_configurations_match_a_fine_grid() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(3);
        for case in 0..60 {
            let c = DVec2::new(rng.random_range(-0.2..0.2), rng.random_range(-0.2..0.2));
            let a = DVec2::new(rng.random_range(0.2..1.0), rng.random_range(-0.5..0.5));
            let b = DVec2::new(rng.random_range(-0.5..0.5), rng.random_range(0.2..1.0));
            let (a, b) = if cross(a, b) > 0.0 { (a, b) } else { (b, a) };
            let poly = [c - a - b, c + a - b, c + a + b, c - a + b];
            let r = rng.random_range(0.05..0.6);
            let nd = 1 + case % 6;
            let centres: Vec<DVec2> = (0..nd)
                .map(|_| DVec2::new(rng.random_range(-1.2..1.2), rng.random_range(-1.2..1.2)))
                .collect();
            let exact = union_discs_polygon_area(&centres, r, &poly);
            let grid = grid_area(&centres, r, &poly, 1200);
            let total = 4.0 * cross(a, b);
            assert!(
                (exact - grid).abs() < 2e-3 * total.max(0.1),
                "case {case}: {exact} vs grid {grid}"
            );
            assert!(exact <= total + 1e-12);
        }
    }

    #[test]
    fn expected_coverage_is_pi_tau_squared_less_overlaps() {
        // Small tau: almost no overlaps.
        let e = expected_coverage(0.02, 32);
        assert!((e / (PI * 0.0004) - 1.0).abs() < 2e-3, "{e}");
        // tau = 0.1: overlaps take a little, bounded by the Poisson value 1 - exp(-pi tau^2)
        // (a jittered grid is more regular than Poisson, so it overlaps less).
        let e = expected_coverage(0.1, 48);
        let pi_t2 = PI * 0.01;
        assert!(e < pi_t2 && e > 1.0 - (-pi_t2).exp(), "{e}");
        // tau = 1: every point is covered unless no point is within 1, which is rare but possible.
        let e = expected_coverage(1.0, 24);
        assert!(e > 0.99 && e <= 1.0, "{e}");
        // Converged in n.
        assert!((expected_coverage(0.3, 32) - expected_coverage(0.3, 64)).abs() < 1e-5);
    }
}
