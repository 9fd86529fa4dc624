//! The area of a convex polygon inside a thick segment's quad (METHOD.md 9.1's exact
//! footprint coverage): Sutherland-Hodgman clipping against each edge of a convex clipper.
//! A quad that is not convex (a short segment at a sharp joint) is clipped as its two
//! triangles, split along the diagonal that keeps them inside it.

use glam::DVec2;

/// Most vertices a clipped polygon can reach: a quadrilateral clipped by 4 half-planes.
const MAX_VERTICES: usize = 12;

type Poly = arrayvec::ArrayVec<DVec2, MAX_VERTICES>;

/// Twice the signed area of the triangle `(a, b, c)` (positive counter-clockwise).
#[inline]
fn cross3(a: DVec2, b: DVec2, c: DVec2) -> f64 {
    (b - a).perp_dot(c - a)
}

/// Whether the counter-clockwise quad `q` is convex (degenerate edges allowed).
#[inline]
fn is_convex(q: &[DVec2; 4]) -> bool {
    (0..4).all(|i| cross3(q[i], q[(i + 1) % 4], q[(i + 2) % 4]) >= 0.0)
}

/// The quad as convex pieces: itself, or its two triangles.
fn pieces(q: &[DVec2; 4]) -> arrayvec::ArrayVec<arrayvec::ArrayVec<DVec2, 4>, 2> {
    let mut out = arrayvec::ArrayVec::new();
    if is_convex(q) {
        out.push(q.iter().copied().collect());
        return out;
    }
    // The diagonal from the reflex vertex keeps both triangles inside a simple quad.
    let reflex = (0..4)
        .find(|&i| cross3(q[(i + 3) % 4], q[i], q[(i + 1) % 4]) < 0.0)
        .unwrap_or(0);
    let (a, b, c, d) = (
        q[reflex],
        q[(reflex + 1) % 4],
        q[(reflex + 2) % 4],
        q[(reflex + 3) % 4],
    );
    for t in [[a, b, c], [a, c, d]] {
        // A self-intersecting quad's inverted triangle covers nothing.
        if cross3(t[0], t[1], t[2]) > 0.0 {
            out.push(t.into_iter().collect());
        }
    }
    out
}

/// The area of `poly` (convex, counter-clockwise, at most 4 vertices) inside the quad `q`
/// (counter-clockwise).
pub fn clipped_area(poly: &[DVec2; 4], q: &[DVec2; 4]) -> f64 {
    pieces(q).iter().map(|c| clip_convex(poly, c)).sum()
}

/// The area of `poly` inside the convex counter-clockwise polygon `clipper`.
fn clip_convex(poly: &[DVec2; 4], clipper: &[DVec2]) -> f64 {
    let mut cur: Poly = poly.iter().copied().collect();
    let n = clipper.len();
    for i in 0..n {
        let (a, b) = (clipper[i], clipper[(i + 1) % n]);
        let e = b - a;
        if e == DVec2::ZERO {
            continue;
        }
        let side = |p: DVec2| e.perp_dot(p - a);
        let mut next = Poly::new();
        for k in 0..cur.len() {
            let (p, q) = (cur[k], cur[(k + 1) % cur.len()]);
            let (sp, sq) = (side(p), side(q));
            if sp >= 0.0 {
                next.push(p);
            }
            if (sp >= 0.0) != (sq >= 0.0) {
                next.push(p + (q - p) * (sp / (sp - sq)));
            }
        }
        if next.len() < 3 {
            return 0.0;
        }
        cur = next;
    }
    let mut twice = 0.0;
    for k in 0..cur.len() {
        twice += cur[k].perp_dot(cur[(k + 1) % cur.len()]);
    }
    (0.5 * twice).max(0.0)
}

/// Whether point `p` lies in the quad `q` (counter-clockwise, boundary included).
pub fn convex_contains(q: &[DVec2; 4], p: DVec2) -> bool {
    pieces(q).iter().any(|c| {
        let n = c.len();
        (0..n).all(|i| (c[(i + 1) % n] - c[i]).perp_dot(p - c[i]) >= 0.0)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square(lo: f64, hi: f64) -> [DVec2; 4] {
        [
            DVec2::new(lo, lo),
            DVec2::new(hi, lo),
            DVec2::new(hi, hi),
            DVec2::new(lo, hi),
        ]
    }

    #[test]
    fn overlapping_squares_clip_to_their_intersection() {
        let a = square(0.0, 2.0);
        let b = square(1.0, 3.0);
        assert!((clipped_area(&a, &b) - 1.0).abs() < 1e-12);
        assert!((clipped_area(&a, &a) - 4.0).abs() < 1e-12);
        assert_eq!(clipped_area(&a, &square(5.0, 6.0)), 0.0);
    }

    #[test]
    fn a_rotated_square_in_a_square_keeps_the_octagon() {
        // A unit square rotated 45 degrees about the centre of [0,1]^2 clipped by it: an
        // octagon of area 2 (sqrt 2 - 1) ... computed independently: the square minus four
        // corner triangles of legs (1 - 1/sqrt 2).
        let c = DVec2::splat(0.5);
        let r = std::f64::consts::FRAC_1_SQRT_2;
        let rot: [DVec2; 4] = std::array::from_fn(|i| {
            let a = std::f64::consts::FRAC_PI_2 * i as f64;
            c + DVec2::new(a.cos(), a.sin()) * r
        });
        let leg = 1.0 - r;
        let expected = 1.0 - 4.0 * 0.5 * leg * leg;
        assert!((clipped_area(&square(0.0, 1.0), &rot) - expected).abs() < 1e-12);
    }

    #[test]
    fn a_non_convex_quad_is_clipped_as_its_triangles() {
        // An arrow-head quad with a reflex vertex at (1, 0.5): area 1 - 0.5 = 0.5 of [0,1]^2...
        let q = [
            DVec2::new(0.0, 0.0),
            DVec2::new(2.0, 0.0),
            DVec2::new(1.0, 0.5),
            DVec2::new(0.0, 2.0),
        ];
        // Monte Carlo-free check: the quad's own area (shoelace) when the footprint covers it.
        let shoelace = 0.5 * (0..4).map(|i| q[i].perp_dot(q[(i + 1) % 4])).sum::<f64>();
        let big = square(-1.0, 3.0);
        assert!((clipped_area(&big, &q) - shoelace).abs() < 1e-12);
        assert!(convex_contains(&q, DVec2::new(0.2, 1.5)));
        assert!(!convex_contains(&q, DVec2::new(1.5, 1.0)));
    }
}
