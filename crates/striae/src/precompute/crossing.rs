//! Two grooves crossing, traced in 3D (METHOD.md 8.3 and "Ours, for 8.3": crossings): the
//! renderer's traced glass walls at a hit that two scratches cover.
//!
//! Groove A is the extruded groove of [`crate::precompute::groove`] (across `x`, along `y`, the
//! opening `[-1/2, 1/2]` at `z = 0`); groove B is the same profile turned about `z` so that its
//! across axis is `b`, and shifted so that the entry line's point on `z = 0` lies at `at` across
//! B's opening. Where two grooves cross, the void is their union, as the explicit geometry
//! carves it: a point of one groove's wall that lies inside the other groove's void is no
//! surface. Each void is an extruded polygon, so a wall hit is kept or passed through after one
//! point-in-polygon test in the other groove's cross-section. The rest is the 2.5D tracer's:
//! smooth glass walls and the smooth flat surface beside the openings (reflection, refraction or
//! total internal reflection by the exact Fresnel reflectance), paths from inside that meet
//! neither groove given up as missed, and the same counter-based random stream per path, so
//! that two parallel grooves trace exactly as the 2.5D tracer traces their union's profile
//! (the tests).

use crate::precompute::cross_section::{CrossSection, T_EPS};
use crate::precompute::groove::{smooth_interface, totally_reflected, GrooveExit, PathDraws};

/// The second groove at a crossing, placed in the first groove's frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Partner {
    /// B's across axis `b = t x n` (METHOD.md section 1) in A's frame: a unit `(x, y)`.
    pub across: [f64; 2],
    /// Where the entry line meets `z = 0`, across B's opening (`[-1/2, 1/2]` inside it, in
    /// B's widths).
    pub at: f64,
    /// B's width over A's (its depth in proportion).
    pub width: f64,
}

/// How a traced path ended (of a crossing, or of one groove,
/// [`crate::precompute::groove::GroovePaths::trace_from`]).
#[derive(Clone, Copy, Debug)]
pub enum CrossingEnd {
    /// With nothing ahead: into the air (up) or the bulk (down).
    Left(GrooveExit),
    /// From inside, meeting no groove.
    Missed,
    /// Out of bounces.
    Lost,
}

/// The two grooves as the ray queries see them: groove `g`'s cross-section coordinates of a
/// point `q`, in its own widths, are `k_g (b_g . (q.x, q.y), q.z) + (off_g, 0)`.
pub(crate) struct Crossing<'a> {
    cs: &'a CrossSection,
    ior: f64,
    b: [[f64; 2]; 2],
    off: [f64; 2],
    k: [f64; 2],
}

impl<'a> Crossing<'a> {
    /// The grooves of cross-section `cs` (glass of index `ior`) for an entry line through
    /// `(x0, 0, 0)`: A through it at `x0`, B as `partner` places it.
    pub fn new(cs: &'a CrossSection, ior: f64, x0: f64, partner: Partner) -> Self {
        let b = partner.across;
        let k = 1.0 / partner.width;
        Crossing {
            cs,
            ior,
            b: [[1.0, 0.0], b],
            off: [0.0, partner.at - k * b[0] * x0],
            k: [1.0, k],
        }
    }

    /// `q` in groove `g`'s cross-section.
    #[inline]
    fn local(&self, g: usize, q: [f64; 3]) -> [f64; 2] {
        let k = self.k[g];
        let s = k * (self.b[g][0] * q[0] + self.b[g][1] * q[1]) + self.off[g];
        [s, k * q[2]]
    }

    /// Whether `q` lies strictly inside groove `g`'s void: below the opening and above the
    /// profile, by the crossing number of the ray from `q` toward `+x` in the cross-section
    /// (the opening, at `z = 0`, never meets it).
    fn in_void(&self, g: usize, q: [f64; 3]) -> bool {
        let [s, z] = self.local(g, q);
        if !(z < 0.0 && s.abs() < 0.5) {
            return false;
        }
        let mut inside = false;
        for seg in &self.cs.segs {
            let (z0, z1) = (seg.p[1], seg.p[1] + seg.e[1]);
            if (z0 > z) != (z1 > z) && seg.p[0] + (z - z0) / seg.e[1] * seg.e[0] > s {
                inside = !inside;
            }
        }
        inside
    }

    /// The nearest point of the union's boundary along `pos + t d`, `t > t_min`, skipping the
    /// segment `skip` last hit: `(groove, segment, t)`. A path in the void meets walls from
    /// their void side, one in the object from theirs (`in_object`): the nearest such wall hit
    /// of either groove, passed through while it lies inside the other groove's void.
    fn nearest(
        &self,
        pos: [f64; 3],
        d: [f64; 3],
        in_object: bool,
        mut skip: (usize, usize),
        mut t_min: f64,
    ) -> Option<(usize, usize, f64)> {
        loop {
            let mut best = None;
            let mut best_t = f64::INFINITY;
            for g in 0..2 {
                let o = self.local(g, pos);
                let k = self.k[g];
                let d2 = [k * (self.b[g][0] * d[0] + self.b[g][1] * d[1]), k * d[2]];
                for (i, s) in self.cs.segs.iter().enumerate() {
                    // Positive where the path meets the segment from the void (its normal side).
                    let denom = d2[0] * s.e[1] - d2[1] * s.e[0];
                    let facing = if in_object { -denom } else { denom };
                    if facing <= 0.0 || (g, i) == skip {
                        continue;
                    }
                    let w = [s.p[0] - o[0], s.p[1] - o[1]];
                    let t = (w[0] * s.e[1] - w[1] * s.e[0]) / denom;
                    let u = (w[0] * d2[1] - w[1] * d2[0]) / denom;
                    if t > t_min && t < best_t && (-1e-12..=1.0 + 1e-12).contains(&u) {
                        best = Some((g, i));
                        best_t = t;
                    }
                }
            }
            let (g, i) = best?;
            let q = [
                pos[0] + best_t * d[0],
                pos[1] + best_t * d[1],
                pos[2] + best_t * d[2],
            ];
            if !self.in_void(1 - g, q) {
                return Some((g, i, best_t));
            }
            // Inside the other void: no surface there; on past it.
            (skip, t_min) = ((g, i), best_t);
        }
    }

    /// One path along `d0` whose line meets `z = 0` at `(x0, 0)`: from the air there, or from
    /// inside the object (`inside`, starting below both grooves), with its bounces drawn from
    /// `draws` as the 2.5D tracer draws them.
    pub fn run(
        &self,
        x0: f64,
        d0: [f64; 3],
        inside: bool,
        draws: PathDraws,
        max_bounces: usize,
    ) -> CrossingEnd {
        let mut d = d0;
        let (mut pos, mut in_object) = if inside {
            let z = self.cs.z_min * self.k[1].recip().max(1.0) - 1.0;
            ([x0 + z / d[2] * d[0], z / d[2] * d[1], z], true)
        } else {
            ([x0, 0.0, 0.0], false)
        };
        let mut skip = (usize::MAX, usize::MAX);
        // Aimed from inside and not yet in a groove.
        let mut aimed = inside;
        let left = |d: [f64; 3], in_object: bool| {
            CrossingEnd::Left(GrooveExit {
                d,
                in_object,
                w: 1.0,
                from: None,
            })
        };
        for bounce in 0..max_bounces {
            let u = draws.fresnel(bounce);
            let t_min = if bounce == 0 { -1e-12 } else { T_EPS };
            let hit = self.nearest(pos, d, in_object, skip, t_min);
            let t_flat = if in_object && d[2] > 0.0 {
                -pos[2] / d[2]
            } else {
                f64::INFINITY
            };
            match hit {
                Some((g, k, t)) if t < t_flat => {
                    aimed = false;
                    pos = [pos[0] + t * d[0], pos[1] + t * d[1], pos[2] + t * d[2]];
                    skip = (g, k);
                    let n2 = self.cs.segs[k].n;
                    let n = [n2[0] * self.b[g][0], n2[0] * self.b[g][1], n2[1]];
                    let eta = if in_object { 1.0 / self.ior } else { self.ior };
                    smooth_dielectric(&mut d, &mut in_object, n, eta, u);
                }
                _ if !in_object => return left(d, false),
                _ if aimed && !(t_flat.is_finite() && totally_reflected(d, self.ior)) => {
                    return CrossingEnd::Missed
                }
                _ if t_flat.is_finite() => {
                    pos = [pos[0] + t_flat * d[0], pos[1] + t_flat * d[1], 0.0];
                    skip = (usize::MAX, usize::MAX);
                    smooth_dielectric(&mut d, &mut in_object, [0.0, 0.0, -1.0], 1.0 / self.ior, u);
                }
                _ => return left(d, true),
            }
        }
        CrossingEnd::Lost
    }
}

/// [`smooth_interface`] for a normal `n` pointing either way: turned to face the ray first.
fn smooth_dielectric(d: &mut [f64; 3], in_object: &mut bool, n: [f64; 3], eta: f64, u: f64) {
    let dn = d[0] * n[0] + d[1] * n[1] + d[2] * n[2];
    let (n, cos_i) = if dn > 0.0 {
        ([-n[0], -n[1], -n[2]], dn)
    } else {
        (n, -dn)
    };
    smooth_interface(d, in_object, n, cos_i, eta, u);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hash::mix64;
    use crate::precompute::groove::GroovePaths;
    use crate::precompute::profile::Profile;

    /// Two parallel V grooves `delta` apart trace as the 2.5D tracer traces their union's
    /// profile (scaled to a unit opening), path by path: the same walls, the same flat surface,
    /// the same random stream, from the air and from inside.
    #[test]
    fn parallel_grooves_trace_as_their_union_profile() {
        let v = Profile::parse("v:angle=90").unwrap();
        let cs = CrossSection::new(&v);
        for delta in [0.3, 0.7] {
            // The union of V's at 0 and `delta`: the ridge between them at `delta / 2`.
            let w = 1.0 + delta;
            let pts = [
                [-0.5, 0.0],
                [0.0, -0.5],
                [0.5 * delta, -0.5 + 0.5 * delta],
                [delta, -0.5],
                [delta + 0.5, 0.0],
            ];
            let union = Profile::from_points(
                "union",
                pts.iter()
                    .map(|p| [(p[0] + 0.5) / w - 0.5, p[1] / w])
                    .collect(),
            )
            .unwrap();
            let paths = GroovePaths::new(&union, 1.5);
            let (mut same, mut n) = (0, 0);
            for k in 0..4000u64 {
                let key = mix64(k ^ 0x5eed);
                let h = |i: u64| (mix64(key ^ i) >> 11) as f64 / (1u64 << 53) as f64;
                let (theta, phi) = (1.5 * h(1), std::f64::consts::TAU * h(2));
                let inside = k % 2 == 1;
                let z = if inside { theta.cos() } else { -theta.cos() };
                let d0 = [theta.sin() * phi.cos(), theta.sin() * phi.sin(), z];
                // An entry line through A's opening (or, from inside, beside it too).
                let x0 = if inside { 2.0 * h(3) - 1.0 } else { h(3) - 0.5 };
                let partner = Partner {
                    across: [1.0, 0.0],
                    at: x0 - delta,
                    width: 1.0,
                };
                let crossing = Crossing::new(&cs, 1.5, x0, partner);
                let end = crossing.run(x0, d0, inside, PathDraws::new(key), 256);
                let flat = paths.run_from((x0 + 0.5) / w - 0.5, d0, inside, key);
                n += 1;
                match (end, flat) {
                    (CrossingEnd::Left(a), Some(Some(b))) => {
                        let err = (0..3).map(|i| (a.d[i] - b.d[i]).abs()).fold(0.0, f64::max);
                        same += (err < 1e-9 && a.in_object == b.in_object) as usize;
                    }
                    (CrossingEnd::Missed, Some(None)) | (CrossingEnd::Lost, None) => same += 1,
                    _ => {}
                }
            }
            assert!(
                same as f64 >= 0.999 * n as f64,
                "delta {delta}: {same} of {n}"
            );
        }
    }

    /// Smooth glass grooves lose nothing where they cross: every path through the union,
    /// from the air and from inside, at any angle, width and place, leaves with a unit
    /// direction (none runs out of bounces), and from the air both sides are reached.
    #[test]
    fn crossing_paths_all_leave() {
        let paths = GroovePaths::new(&Profile::parse("round:depth=0.3,segments=16").unwrap(), 1.5);
        let (mut left, mut up, n) = (0, 0, 20_000u64);
        for k in 0..n {
            let key = mix64(k ^ 0xfeed);
            let h = |i: u64| (mix64(key ^ i) >> 11) as f64 / (1u64 << 53) as f64;
            let angle = std::f64::consts::PI * h(1);
            let partner = Partner {
                across: [angle.cos(), angle.sin()],
                at: h(2) - 0.5,
                width: 0.3 + 2.0 * h(3),
            };
            let (theta, phi) = (1.5 * h(4), std::f64::consts::TAU * h(5));
            let z = if k % 2 == 1 {
                theta.cos()
            } else {
                -theta.cos()
            };
            let d0 = [theta.sin() * phi.cos(), theta.sin() * phi.sin(), z];
            if let Some(e) = paths.trace(d0, h(6), None, key, Some(partner), 0.0) {
                let len = (e.d[0] * e.d[0] + e.d[1] * e.d[1] + e.d[2] * e.d[2]).sqrt();
                assert!((len - 1.0).abs() < 1e-9 && e.w == 1.0, "{e:?}");
                left += 1;
                up += (k % 2 == 0 && e.d[2] > 0.0) as u64;
            }
        }
        assert!(left as f64 >= 0.9995 * n as f64, "{left} of {n} left");
        assert!(
            up > n / 100 && up < n / 4,
            "reflected from the air: {up} of {}",
            n / 2
        );
    }

    /// Crossing grooves: the first wall a ray from the air meets is the union's floor, the
    /// deeper of the two profiles, found by marching down the ray (an independent height-field
    /// search), for V and round grooves at several angles.
    #[test]
    fn first_hit_is_the_deeper_floor() {
        for spec in ["v:angle=90", "round:depth=0.3,segments=16"] {
            let p = Profile::parse(spec).unwrap();
            let cs = CrossSection::new(&p);
            // Depth below `z = 0` of the profile at `s` (0 outside the opening).
            let depth = |s: f64| {
                p.points
                    .windows(2)
                    .find(|w| s >= w[0][0] && s <= w[1][0])
                    .map_or(0.0, |w| {
                        -(w[0][1] + (s - w[0][0]) / (w[1][0] - w[0][0]) * (w[1][1] - w[0][1]))
                    })
            };
            let mut checked = 0;
            for k in 0..400u64 {
                let key = mix64(k ^ 0xc0ffee);
                let h = |i: u64| (mix64(key ^ i) >> 11) as f64 / (1u64 << 53) as f64;
                let angle = 0.3 + 2.5 * h(1);
                let partner = Partner {
                    across: [angle.cos(), angle.sin()],
                    at: h(2) - 0.5,
                    width: 0.4 + 1.2 * h(6),
                };
                let x0 = h(3) - 0.5;
                let (theta, phi) = (1.2 * h(4), std::f64::consts::TAU * h(5));
                let d = [
                    theta.sin() * phi.cos(),
                    theta.sin() * phi.sin(),
                    -theta.cos(),
                ];
                let c = Crossing::new(&cs, 1.5, x0, partner);
                let Some((_, _, t)) =
                    c.nearest([x0, 0.0, 0.0], d, false, (usize::MAX, usize::MAX), 0.0)
                else {
                    panic!("{spec}: no floor below an opening");
                };
                let floor = |t: f64| {
                    let q = [x0 + t * d[0], t * d[1], t * d[2]];
                    let (a, b) = (c.local(0, q), c.local(1, q));
                    q[2] + depth(a[0]).max(depth(b[0]) / c.k[1])
                };
                // Above the floor before `t`, on it at `t`.
                let steps = 2000;
                assert!(
                    (1..steps).all(|i| floor(t * i as f64 / steps as f64) > -1e-9),
                    "{spec} ray {k}: below the floor before the hit"
                );
                assert!(floor(t).abs() < 1e-9, "{spec} ray {k}: {}", floor(t));
                checked += 1;
            }
            assert_eq!(checked, 400);
        }
    }
}
