//! The groove's cross-section as ray-traceable geometry (METHOD.md sections 2, 3 and 8.1): the
//! profile's segments in the `(x, z)` plane, with the ray queries both tracers use. The 2D
//! precompute ([`crate::precompute::trace2d`]) traces inside the groove only (air side); the exact 2.5D
//! tracer ([`crate::precompute::groove`]) also traces the object below the profile (glass side) and the
//! flat surface `z = 0` beside the opening.
//!
//! The profile runs from `(-1/2, 0)` to `(1/2, 0)` below `z = 0`, so closed by its opening it is
//! a counter-clockwise simple polygon (validated by [`crate::precompute::profile`]): each segment's normal
//! `n` (to the left of its direction `e`) points into the groove (the air), and a ray inside the
//! groove can only hit a segment from that side (`d x e > 0`).

use crate::precompute::profile::Profile;

/// One profile segment from `p` to `p + e`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Segment {
    pub p: [f64; 2],
    pub e: [f64; 2],
    /// Unit normal, pointing to the left of `e` (into the groove: up for a floor traversed
    /// left to right).
    pub n: [f64; 2],
    /// Unit tangent `e / |e|`.
    pub t: [f64; 2],
}

/// The profile as segments, with ray queries.
#[derive(Clone, Debug)]
pub(crate) struct CrossSection {
    pub segs: Vec<Segment>,
    /// The groove closed by its opening is a convex polygon (V, round, trapezoid, flat): a
    /// ray leaving a wall escapes iff it points between the opening's corners.
    pub convex: bool,
    /// The profile's deepest `z` (`<= 0`).
    pub z_min: f64,
}

/// Which side of a segment a ray hits ([`CrossSection::nearest_either_side`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Side {
    /// From the groove (the air above the profile): `d . n < 0`.
    Groove,
    /// From below the profile (inside the object): `d . n > 0`.
    Object,
}

/// The parameter below which a hit is the ray's own origin (rays leave a wall from its
/// surface; the skipped segment already excludes the wall itself).
pub(crate) const T_EPS: f64 = 1e-10;

impl CrossSection {
    pub fn new(profile: &Profile) -> Self {
        let segs = profile
            .points
            .windows(2)
            .map(|w| {
                let e = [w[1][0] - w[0][0], w[1][1] - w[0][1]];
                let l = e[0].hypot(e[1]);
                let t = [e[0] / l, e[1] / l];
                Segment {
                    p: w[0],
                    e,
                    n: [-t[1], t[0]],
                    t,
                }
            })
            .collect::<Vec<Segment>>();
        // Counter-clockwise polygon: convex iff it turns left (or goes straight) at every
        // profile vertex (at the opening's corners it always does, the profile being below).
        let convex = segs
            .windows(2)
            .all(|w| w[0].t[0] * w[1].t[1] - w[0].t[1] * w[1].t[0] >= -1e-12);
        let z_min = profile.points.iter().map(|p| p[1]).fold(0.0, f64::min);
        CrossSection {
            segs,
            convex,
            z_min,
        }
    }

    /// The angle of segment `k`'s normal from the vertical, `atan2(n.x, n.z)`.
    pub fn normal_angle(&self, k: usize) -> f64 {
        let n = self.segs[k].n;
        n[0].atan2(n[1])
    }

    /// For a convex two-wall groove (a V): a ray leaving wall `seg` that does not escape hits
    /// the other wall; its line parameter in closed form (no culling loop). `None` only when
    /// round-off makes the ray parallel to or leave the other wall.
    #[inline]
    pub fn other_wall_hit(&self, o: [f64; 2], d: [f64; 2], seg: usize) -> Option<(usize, f64)> {
        let k = 1 - seg;
        let s = &self.segs[k];
        let denom = d[0] * s.e[1] - d[1] * s.e[0];
        let t = ((s.p[0] - o[0]) * s.e[1] - (s.p[1] - o[1]) * s.e[0]) / denom;
        (denom > 0.0 && t > 0.0).then_some((k, t))
    }

    /// In a convex groove: whether a ray from `pos` (on a wall) along `dir` leaves through the
    /// opening, i.e. points between the directions to the opening's corners `(-1/2, 0)` and
    /// `(1/2, 0)`.
    #[inline(always)]
    pub fn escapes_convex(pos: [f64; 2], dir: [f64; 2]) -> bool {
        let (vl, vr) = ([-0.5 - pos[0], -pos[1]], [0.5 - pos[0], -pos[1]]);
        let right_of_left = vl[0] * dir[1] - vl[1] * dir[0] <= 0.0;
        let left_of_right = vr[0] * dir[1] - vr[1] * dir[0] >= 0.0;
        right_of_left & left_of_right
    }

    /// Nearest wall hit from the groove side of the ray `o + t d` with `t > t_min`, skipping
    /// segment `skip`.
    ///
    /// A ray inside the groove can only hit a wall from its inner side, where `d x e > 0`:
    /// other segments are culled, and the comparisons are division-free.
    #[inline]
    pub fn nearest(
        &self,
        o: [f64; 2],
        d: [f64; 2],
        skip: usize,
        t_min: f64,
    ) -> Option<(usize, f64)> {
        let mut best = usize::MAX;
        // Best hit as the fraction num/den (den > 0), initially +infinity.
        let (mut best_num, mut best_den) = (1.0f64, 0.0f64);
        for (k, s) in self.segs.iter().enumerate() {
            let denom = d[0] * s.e[1] - d[1] * s.e[0];
            let w = [s.p[0] - o[0], s.p[1] - o[1]];
            let t_num = w[0] * s.e[1] - w[1] * s.e[0];
            let u_num = w[0] * d[1] - w[1] * d[0];
            let tol = 1e-12 * denom;
            // Non-short-circuit `&` so that the choice compiles to selects, not branches
            // (the outcome is unpredictable and mispredictions dominated the cost).
            let ok = (denom > 0.0)
                & (k != skip)
                & (t_num > t_min * denom)
                & (t_num * best_den < best_num * denom)
                & (u_num >= -tol)
                & (u_num <= denom + tol);
            best = if ok { k } else { best };
            best_num = if ok { t_num } else { best_num };
            best_den = if ok { denom } else { best_den };
        }
        (best != usize::MAX).then(|| (best, best_num / best_den))
    }

    /// Nearest wall hit from either side (the 2.5D tracer's rays also travel inside the
    /// object below the profile): the segment, the line parameter and the side hit.
    #[inline]
    pub fn nearest_either_side(
        &self,
        o: [f64; 2],
        d: [f64; 2],
        skip: usize,
        t_min: f64,
    ) -> Option<(usize, f64, Side)> {
        let mut best = usize::MAX;
        let (mut best_num, mut best_den) = (1.0f64, 0.0f64);
        for (k, s) in self.segs.iter().enumerate() {
            let denom = d[0] * s.e[1] - d[1] * s.e[0];
            // Flip the signs so that the denominator is positive whichever side is hit.
            let sign = if denom < 0.0 { -1.0 } else { 1.0 };
            let den = denom * sign;
            let w = [s.p[0] - o[0], s.p[1] - o[1]];
            let t_num = (w[0] * s.e[1] - w[1] * s.e[0]) * sign;
            let u_num = (w[0] * d[1] - w[1] * d[0]) * sign;
            let tol = 1e-12 * den;
            let ok = (den > 0.0)
                & (k != skip)
                & (t_num > t_min * den)
                & (t_num * best_den < best_num * den)
                & (u_num >= -tol)
                & (u_num <= den + tol);
            if ok {
                best = k;
                best_num = t_num;
                best_den = den;
            }
        }
        (best != usize::MAX).then(|| {
            let s = &self.segs[best];
            let side = if d[0] * s.n[0] + d[1] * s.n[1] < 0.0 {
                Side::Groove
            } else {
                Side::Object
            };
            (best, best_num / best_den, side)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn v_groove_hits_from_both_sides() {
        // 90-degree V: left wall z = -x - 1/2, right wall z = x - 1/2.
        let cs = CrossSection::new(&Profile::parse("v:angle=90").unwrap());
        assert!(cs.convex);
        assert!((cs.z_min + 0.5).abs() < 1e-12);
        // Straight down from (-0.25, 0): the left wall at z = -0.25, from the groove.
        let (k, t) = cs
            .nearest([-0.25, 0.0], [0.0, -1.0], usize::MAX, 0.0)
            .unwrap();
        assert_eq!(k, 0);
        assert!((t - 0.25).abs() < 1e-12);
        let (k2, t2, side) = cs
            .nearest_either_side([-0.25, 0.0], [0.0, -1.0], usize::MAX, 0.0)
            .unwrap();
        assert_eq!((k2, side), (0, Side::Groove));
        assert!((t2 - t).abs() < 1e-15);
        // Straight up from (0.25, -2): the right wall at z = -0.25, from the object.
        let (k, t, side) = cs
            .nearest_either_side([0.25, -2.0], [0.0, 1.0], usize::MAX, 0.0)
            .unwrap();
        assert_eq!((k, side), (1, Side::Object));
        assert!((t - 1.75).abs() < 1e-12);
        // The one-sided query does not see it.
        assert!(cs
            .nearest([0.25, -2.0], [0.0, 1.0], usize::MAX, 0.0)
            .is_none());
        // Beside the groove, upward: nothing.
        assert!(cs
            .nearest_either_side([0.75, -2.0], [0.0, 1.0], usize::MAX, 0.0)
            .is_none());
        // Escape test: from the bottom straight up leaves, sideways does not.
        assert!(CrossSection::escapes_convex([0.0, -0.5], [0.0, 1.0]));
        assert!(!CrossSection::escapes_convex([0.0, -0.5], [1.0, 0.2]));
    }
}
