//! From a curve's centre line to its scratches (METHOD.md 9.1-9.2): Bézier flattening to a
//! stated tolerance, and the stroke's ends, dashes and wear ([`StrokeStyle`]).
//!
//! * Taper: over `taper` (drawing units) at each end the half-width follows the seed's ellipse
//!   tips, `w(s) = w_0 sqrt(1 - (1 - s / taper)^2)` (METHOD.md 9.2), resolved by
//!   [`TAPER_STATIONS`] vertices `s = taper (1 - cos theta)`; a curve shorter than twice the
//!   taper tapers over half its length from each end. A straight tapered scratch of length `L`
//!   covers `2 w_0 (L - 2 taper + pi taper / 2)`.
//! * Dashes: `dashes = [on, off, on, off, ...]` (drawing units, as SVG's `stroke-dasharray`,
//!   repeated; an odd count is repeated twice, as SVG does) starting `dash_offset` into the
//!   pattern: each dash is a scratch of its own, cut from the tapered curve (so dashes near an
//!   end are thinner).
//! * Wear: the depth ratio `d(s) = depth (1 - wear n(s / wear_length))`, `n` a smooth value
//!   noise in `[0, 1]` (hashed lattice values, smoothstep between them) seeded per curve, with
//!   vertices every quarter `wear_length` so that the polyline follows it.

use super::{CurveError, Polyline};
use glam::DVec2;

/// Vertices that resolve each tapered end.
pub const TAPER_STATIONS: usize = 16;
/// A flattened curve stays within this fraction of the stroke's width of the true curve.
pub const FLATTEN_TOLERANCE: f64 = 0.02;
/// Most vertices one curve may flatten to (a guard against a width far below the drawing's
/// scale; the set's own limit is [`super::MAX_SEGMENTS`]).
pub const MAX_CURVE_VERTICES: usize = 1 << 20;

/// How a centre line becomes scratches (see the module notes). All lengths in the drawing's
/// units.
#[derive(Clone, Debug, PartialEq)]
pub struct StrokeStyle {
    pub taper: f64,
    pub dashes: Vec<f64>,
    pub dash_offset: f64,
    /// The depth ratio (over the profile's) where unworn, in `(0, 1]`.
    pub depth: f64,
    /// How much of the depth wear takes at most, in `[0, 1)`.
    pub wear: f64,
    /// The correlation length of the wear along the scratch (> 0 where `wear > 0`).
    pub wear_length: f64,
    pub seed: u64,
}

impl Default for StrokeStyle {
    fn default() -> Self {
        StrokeStyle {
            taper: 0.0,
            dashes: Vec::new(),
            dash_offset: 0.0,
            depth: 1.0,
            wear: 0.0,
            wear_length: 0.0,
            seed: 0,
        }
    }
}

fn param(key: &'static str, value: impl std::fmt::Debug, why: &str) -> CurveError {
    CurveError::Param {
        key,
        value: format!("{value:?}"),
        why: why.to_string(),
    }
}

impl StrokeStyle {
    /// Check every field; the error names the key.
    pub fn validate(&self) -> Result<(), CurveError> {
        if !(self.taper.is_finite() && self.taper >= 0.0) {
            return Err(param("taper", self.taper, "must be a finite length >= 0"));
        }
        if let Some(d) = self.dashes.iter().find(|d| !(d.is_finite() && **d >= 0.0)) {
            return Err(param("dashes", d, "dash lengths must be finite and >= 0"));
        }
        if !self.dashes.is_empty() && self.dashes.iter().sum::<f64>() <= 0.0 {
            return Err(param(
                "dashes",
                &self.dashes,
                "the pattern must have a positive length",
            ));
        }
        if !self.dash_offset.is_finite() {
            return Err(param("dash_offset", self.dash_offset, "must be finite"));
        }
        if !(self.depth > 0.0 && self.depth <= 1.0) {
            return Err(param(
                "depth",
                self.depth,
                "a depth ratio over the profile's must lie in (0, 1]",
            ));
        }
        if !(self.wear >= 0.0 && self.wear < 1.0) {
            return Err(param("wear", self.wear, "must lie in [0, 1)"));
        }
        if self.wear > 0.0 && !(self.wear_length.is_finite() && self.wear_length > 0.0) {
            return Err(param(
                "wear_length",
                self.wear_length,
                "must be a finite length > 0 where wear > 0",
            ));
        }
        Ok(())
    }

    /// The scratches of one centre line of half-width `hw` (the curve's `index` seeds its
    /// wear): the tapered, worn polyline cut into its dashes. `points` need not be free of
    /// duplicates; fewer than 2 distinct points give no scratch.
    pub fn apply(&self, points: &[DVec2], hw: f64, index: u64) -> Vec<Polyline> {
        let Some(line) = Polyline::uniform(points.to_vec(), hw).deduplicated() else {
            return Vec::new();
        };
        let s = line.arc_lengths();
        let total = *s.last().expect("two points");
        // Stations to insert: tapered ends, wear, dash ends.
        let mut stations = Vec::new();
        let taper = self.taper.min(0.5 * total);
        if taper > 0.0 {
            for k in 1..TAPER_STATIONS {
                let x = taper
                    * (1.0
                        - (std::f64::consts::FRAC_PI_2 * k as f64 / TAPER_STATIONS as f64).cos());
                stations.push(x);
                stations.push(total - x);
            }
        }
        if self.wear > 0.0 {
            let step = 0.25 * self.wear_length;
            let n = ((total / step) as usize).min(MAX_CURVE_VERTICES);
            stations.extend((1..n).map(|k| k as f64 * total / n as f64));
        }
        let dashes = self.dash_intervals(total);
        for &(a, b) in &dashes {
            stations.push(a);
            stations.push(b);
        }
        let (s, p) = resample(&line.points, &s, stations);
        let width = |x: f64| {
            let e = x.min(total - x).max(0.0);
            if taper > 0.0 && e < taper {
                let t = 1.0 - e / taper;
                hw * (1.0 - t * t).max(0.0).sqrt()
            } else {
                hw
            }
        };
        let depth = |x: f64| {
            if self.wear > 0.0 {
                self.depth * (1.0 - self.wear * value_noise(x / self.wear_length, self.seed, index))
            } else {
                self.depth
            }
        };
        let piece = |a: f64, b: f64| -> Option<Polyline> {
            // The vertices of `[a, b]`: `s` is sorted, so a range found by bisection.
            let lo = s.partition_point(|&x| x < a - 1e-12 * total);
            let hi = s.partition_point(|&x| x <= b + 1e-12 * total);
            let idx = lo..hi.max(lo);
            let line = Polyline {
                points: p[idx.clone()].to_vec(),
                half_widths: s[idx.clone()].iter().map(|&x| width(x)).collect(),
                depths: s[idx].iter().map(|&x| depth(x)).collect(),
            };
            line.deduplicated()
                .filter(|l| l.half_widths.iter().any(|&w| w > 0.0))
        };
        if self.dashes.is_empty() {
            piece(0.0, total).into_iter().collect()
        } else {
            dashes.iter().filter_map(|&(a, b)| piece(a, b)).collect()
        }
    }

    /// The "on" intervals of the dash pattern over `[0, total]` (empty without dashes).
    fn dash_intervals(&self, total: f64) -> Vec<(f64, f64)> {
        if self.dashes.is_empty() {
            return Vec::new();
        }
        let mut pattern = self.dashes.clone();
        if pattern.len() % 2 == 1 {
            pattern.extend_from_within(..);
        }
        let period: f64 = pattern.iter().sum();
        // Where the pattern starts: `dash_offset` into it, so position 0 of the curve is
        // `dash_offset mod period` of the pattern.
        let mut x = -self.dash_offset.rem_euclid(period);
        let mut out = Vec::new();
        let mut k = 0;
        while x < total && out.len() < MAX_CURVE_VERTICES {
            let len = pattern[k % pattern.len()];
            let (a, b) = (x, x + len);
            if k % 2 == 0 && b > 0.0 && len > 0.0 {
                out.push((a.max(0.0), b.min(total)));
            }
            x = b;
            k += 1;
        }
        out
    }
}

/// The polyline `points` (arc lengths `s`) with a vertex inserted at each of `stations`
/// (arc lengths inside it); the arc lengths and points, sorted.
fn resample(points: &[DVec2], s: &[f64], mut stations: Vec<f64>) -> (Vec<f64>, Vec<DVec2>) {
    let total = s[s.len() - 1];
    stations.retain(|&x| x > 0.0 && x < total);
    stations.sort_by(f64::total_cmp);
    let (mut out_s, mut out_p) = (Vec::new(), Vec::new());
    let mut k = 0;
    for i in 0..points.len() {
        if i > 0 {
            while k < stations.len() && stations[k] < s[i] {
                let x = stations[k];
                if x > s[i - 1] {
                    let t = (x - s[i - 1]) / (s[i] - s[i - 1]);
                    out_s.push(x);
                    out_p.push(points[i - 1].lerp(points[i], t));
                }
                k += 1;
            }
        }
        out_s.push(s[i]);
        out_p.push(points[i]);
    }
    (out_s, out_p)
}

/// Smooth value noise in `[0, 1]` at `x`: hashed lattice values, smoothstep between them.
fn value_noise(x: f64, seed: u64, index: u64) -> f64 {
    let i = x.floor();
    let f = x - i;
    let h = |k: i64| {
        let z = crate::hash::mix64(
            seed ^ crate::hash::mix64(index.wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ k as u64),
        );
        crate::hash::unit_from_u32(z >> 32)
    };
    let (a, b) = (h(i as i64), h(i as i64 + 1));
    let t = f * f * (3.0 - 2.0 * f);
    a + (b - a) * t
}

/// Uniform steps that keep a quadratic Bézier within `tol` of its chord polyline:
/// `|B''| / 8 n^2 <= tol`, `|B''| = 2 |p0 - 2 p1 + p2|`.
pub fn quad_steps(p: [DVec2; 3], tol: f64) -> usize {
    let dd = 2.0 * (p[0] - 2.0 * p[1] + p[2]).length();
    steps(dd, tol)
}

/// As [`quad_steps`] for a cubic: `|B''| <= 6 max(|p0 - 2 p1 + p2|, |p1 - 2 p2 + p3|)`.
pub fn cubic_steps(p: [DVec2; 4], tol: f64) -> usize {
    let dd = 6.0
        * (p[0] - 2.0 * p[1] + p[2])
            .length()
            .max((p[1] - 2.0 * p[2] + p[3]).length());
    steps(dd, tol)
}

fn steps(dd: f64, tol: f64) -> usize {
    let n = (dd / (8.0 * tol)).sqrt().ceil();
    if n.is_finite() {
        (n as usize).clamp(1, MAX_CURVE_VERTICES)
    } else {
        MAX_CURVE_VERTICES
    }
}

/// Point `t` of the quadratic Bézier `p`.
pub fn quad_at(p: [DVec2; 3], t: f64) -> DVec2 {
    let u = 1.0 - t;
    p[0] * (u * u) + p[1] * (2.0 * u * t) + p[2] * (t * t)
}

/// Point `t` of the cubic Bézier `p`.
pub fn cubic_at(p: [DVec2; 4], t: f64) -> DVec2 {
    let u = 1.0 - t;
    p[0] * (u * u * u) + p[1] * (3.0 * u * u * t) + p[2] * (3.0 * u * t * t) + p[3] * (t * t * t)
}

/// Vertices of a circular arc about `centre` of `radius` from angle `a0` to `a1` (radians,
/// counter-clockwise where `a1 > a0`) whose chords stay within `tol` of it: the sagitta
/// `r (1 - cos(dtheta / 2)) <= tol`.
pub fn arc_points(centre: DVec2, radius: f64, a0: f64, a1: f64, tol: f64) -> Vec<DVec2> {
    let dmax = if tol >= radius {
        std::f64::consts::FRAC_PI_2
    } else {
        2.0 * (1.0 - tol / radius).acos()
    };
    let n = (((a1 - a0).abs() / dmax.max(1e-9)).ceil() as usize).clamp(2, MAX_CURVE_VERTICES);
    let mut pts: Vec<DVec2> = (0..=n)
        .map(|k| {
            let a = a0 + (a1 - a0) * k as f64 / n as f64;
            centre + radius * DVec2::new(a.cos(), a.sin())
        })
        .collect();
    if (a1 - a0).abs() >= std::f64::consts::TAU {
        // A full circle ends exactly where it starts (a closed curve, `Polyline::mitres`).
        pts[n] = pts[0];
    }
    pts
}
