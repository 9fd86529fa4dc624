//! Generated curves (METHOD.md 9.1, 9.3): polishing swirls and concentric circles, in uv.
//!
//! * `swirl`: `count` circular arcs, the random marks a polishing pad leaves (the circular
//!   halos around a lamp's reflection on car paint or a polished watch case): centre uniform
//!   over the square grown by the largest radius, radius uniform in `radius`, start angle
//!   uniform, span uniform in `arc` (degrees), direction of travel either way.
//! * `circles`: `count` full circles about `centre`, radii evenly spaced over `radius`
//!   (a turned disc, a record, wiper marks: the floating stripe of METHOD.md 9.3), each moved
//!   by up to `jitter` of the spacing at random.
//!
//! Every arc is flattened with chords within [`super::stroke::FLATTEN_TOLERANCE`] of the
//! width, and each draw comes from `(seed, index)` alone.

use super::stroke::{arc_points, StrokeStyle, FLATTEN_TOLERANCE};
use super::{CurveError, Polyline};
use glam::DVec2;
use serde::Deserialize;
use std::f64::consts::TAU;

/// Most arcs or circles a pattern may hold.
pub const MAX_PATTERN_CURVES: usize = 1 << 20;

/// `scratches.pattern`, a table with `kind = "swirl"` or `kind = "circles"`.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
pub enum Pattern {
    Swirl {
        count: usize,
        /// Smallest and largest radius (uv).
        radius: [f64; 2],
        /// Smallest and largest span (degrees).
        #[serde(default = "default_arc")]
        arc: [f64; 2],
        /// Scratch width (uv).
        width: f64,
        #[serde(default)]
        seed: u64,
    },
    Circles {
        #[serde(default = "default_centre")]
        centre: [f64; 2],
        /// Innermost and outermost radius (uv).
        radius: [f64; 2],
        count: usize,
        /// Scratch width (uv).
        width: f64,
        /// Random shift of each radius, as a fraction of the spacing, in `[0, 1]`.
        #[serde(default)]
        jitter: f64,
        #[serde(default)]
        seed: u64,
    },
}

fn default_arc() -> [f64; 2] {
    [20.0, 90.0]
}

fn default_centre() -> [f64; 2] {
    [0.5, 0.5]
}

fn param(key: &'static str, value: impl std::fmt::Debug, why: &str) -> CurveError {
    CurveError::Param {
        key,
        value: format!("{value:?}"),
        why: why.to_string(),
    }
}

/// A uniform number in `[0, 1)` from `(seed, index, k)`.
fn draw(seed: u64, index: u64, k: u64) -> f64 {
    let h = crate::hash::mix64(
        crate::hash::mix64(seed ^ 0x5357_4952_4c53) ^ index.wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ k,
    );
    (h >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

fn check_range(key: &'static str, r: [f64; 2], max: f64) -> Result<(), CurveError> {
    if !(r[0].is_finite() && r[1].is_finite() && r[0] > 0.0 && r[0] <= r[1] && r[1] <= max) {
        return Err(param(
            key,
            r,
            &format!("must be [smallest, largest] with 0 < smallest <= largest <= {max}"),
        ));
    }
    Ok(())
}

impl Pattern {
    /// Check every key; the error names it (`scratches.pattern.KEY`).
    pub fn validate(&self) -> Result<(), CurveError> {
        let (count, width) = match self {
            Pattern::Swirl {
                count,
                radius,
                arc,
                width,
                ..
            } => {
                check_range("pattern.radius", *radius, 1e3)?;
                check_range("pattern.arc", *arc, 360.0)?;
                (*count, *width)
            }
            Pattern::Circles {
                centre,
                radius,
                count,
                width,
                jitter,
                ..
            } => {
                if !centre.iter().all(|c| c.is_finite()) {
                    return Err(param("pattern.centre", centre, "must be finite"));
                }
                check_range("pattern.radius", *radius, 1e3)?;
                if !(0.0..=1.0).contains(jitter) {
                    return Err(param("pattern.jitter", jitter, "must lie in [0, 1]"));
                }
                (*count, *width)
            }
        };
        if !(1..=MAX_PATTERN_CURVES).contains(&count) {
            return Err(param(
                "pattern.count",
                count,
                &format!("must be between 1 and {MAX_PATTERN_CURVES}"),
            ));
        }
        if !(width.is_finite() && width > 0.0) {
            return Err(param(
                "pattern.width",
                width,
                "a scratch width must be finite and > 0",
            ));
        }
        Ok(())
    }

    /// About how many segments the pattern flattens to (before taper and dashes add theirs):
    /// its arcs' spans over the chord angle that keeps them within the flattening tolerance.
    pub fn segments(&self) -> f64 {
        let per_radian = |r: f64, width: f64| {
            let tol = FLATTEN_TOLERANCE * width;
            1.0 / (2.0 * (1.0 - (tol / r).min(1.0)).acos()).max(1e-9)
        };
        match *self {
            Pattern::Swirl {
                count,
                radius,
                arc,
                width,
                ..
            } => count as f64 * arc[1].to_radians() * per_radian(radius[1], width),
            Pattern::Circles {
                count,
                radius,
                width,
                ..
            } => count as f64 * TAU * per_radian(radius[1], width),
        }
    }

    /// The pattern's scratches in uv, each through `style` (taper, dashes, wear); a pattern
    /// that would flatten to more than [`super::MAX_SEGMENTS`] is refused up front, with the
    /// figure.
    pub fn polylines(&self, style: &StrokeStyle) -> Result<Vec<Polyline>, CurveError> {
        self.validate()?;
        style.validate()?;
        let segments = self.segments();
        if segments > super::MAX_SEGMENTS as f64 {
            return Err(CurveError::TooManySegments(segments as usize));
        }
        let mut out = Vec::new();
        match *self {
            Pattern::Swirl {
                count,
                radius,
                arc,
                width,
                seed,
            } => {
                let tol = FLATTEN_TOLERANCE * width;
                for i in 0..count as u64 {
                    let grow = radius[1];
                    let c = DVec2::new(
                        -grow + (1.0 + 2.0 * grow) * draw(seed, i, 0),
                        -grow + (1.0 + 2.0 * grow) * draw(seed, i, 1),
                    );
                    let r = radius[0] + (radius[1] - radius[0]) * draw(seed, i, 2);
                    let a0 = TAU * draw(seed, i, 3);
                    let span = (arc[0] + (arc[1] - arc[0]) * draw(seed, i, 4)).to_radians();
                    let span = if draw(seed, i, 5) < 0.5 { span } else { -span };
                    let pts = arc_points(c, r, a0, a0 + span, tol);
                    out.extend(style.apply(&pts, 0.5 * width, i));
                }
            }
            Pattern::Circles {
                centre,
                radius,
                count,
                width,
                jitter,
                seed,
            } => {
                let tol = FLATTEN_TOLERANCE * width;
                let c = DVec2::from(centre);
                let spacing = if count > 1 {
                    (radius[1] - radius[0]) / (count - 1) as f64
                } else {
                    0.0
                };
                for i in 0..count as u64 {
                    let shift = jitter * spacing * (draw(seed, i, 0) - 0.5);
                    let r = (radius[0] + spacing * i as f64 + shift).max(0.5 * width);
                    let a0 = TAU * draw(seed, i, 1);
                    let pts = arc_points(c, r, a0, a0 + TAU, tol);
                    out.extend(style.apply(&pts, 0.5 * width, i));
                }
            }
        }
        Ok(out)
    }
}
