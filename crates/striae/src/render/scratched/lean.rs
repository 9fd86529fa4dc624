//! The tapered groove's lean (`lean = true`, METHOD.md 8.3, our option): where on its scratch
//! a lobe takes the lean, and the turn of its frame. A scratch's groove narrows toward its tips,
//! its walls leaning toward its middle by `tan alpha = 2 A |W'(s)|` (`A` the profile's
//! [`crate::precompute::profile::Profile::area`]), exactly so for a V; the seed's extruded groove has none.
//! Traced glass walls take the rate `W'` back from the lobe and lean each wall by it
//! ([`crate::precompute::groove::GroovePaths::trace`]'s `taper`).

use crate::layers::Scratch;
use crate::render::bsdf::ScratchLobe;
use crate::render::shading::ShadingContext;
use glam::DVec2;

/// Where the lean of a tapered groove's walls runs out: `|s/l|` at most this (a tilt of at most
/// `atan(89 A W / L)`: 20 degrees for a 90-degree V at setting 2, `W / L = 1/60`).
const MAX_LEAN_S: f64 = 0.999;

/// Where on a scratch's axis a leaned lobe takes its lean.
#[derive(Clone, Copy)]
pub(super) enum Along {
    /// At the hit (the point test: the hit is on the scratch, or beside its ridge).
    Hit,
    /// At the hit where it lies on the scratch; else (the footprint's coverage, where the hit
    /// may lie off the scratch the footprint holds) at a point of the scratch's part within
    /// the footprint, placed by the given uniform number.
    Footprint(f32),
}

/// `lobe` (scratch `sc`'s, with the unleaned frame) leaned as the tapered groove's walls lean
/// at `s/l` (`lean` twice the profile's area, [`super::ScratchedMaterial::with_lean`]): `W' =
/// -2 w (s/l) / (l sqrt(1 - (s/l)^2))` with the scratch's world half-length `l` and half-width
/// `w` (the texture ellipse mapped to the face, as the explicit grooves take it,
/// [`crate::render::geometry::carve`]); the normal tilts toward the scratch's middle.
pub(super) fn leaned(
    lobe: ScratchLobe,
    lean: f64,
    ctx: &ShadingContext,
    sc: &Scratch,
    along: Along,
) -> ScratchLobe {
    let d = sc.direction;
    let map = |v: DVec2| ctx.dpdu.as_dvec3() * v.x + ctx.dpdv.as_dvec3() * v.y;
    let along_world = map(d);
    let along_len = along_world.length();
    let area = along_world.cross(map(d.perp())).length();
    let (l, w) = sc.mapped_half_axes(along_len, area);
    let s = lean_place(ctx, sc, along).clamp(-MAX_LEAN_S, MAX_LEAN_S);
    let tan = lean * -2.0 * w * s / (l * (1.0 - s * s).sqrt());
    if tan.is_finite() {
        lobe.leaned(tan as f32)
    } else {
        lobe
    }
}

/// `s/l` of the point of scratch `sc` whose lean a lobe takes ([`Along`]). Off the scratch,
/// the scratch's part within the pixel's footprint (centred on the pixel's centre,
/// [`crate::layers::CoverageCache::of_pixel`]) spans `s/l` in `[a - e, a + e]` (`a` the
/// centre's, `e` the footprint's half-extent along the axis), clipped to `[-1, 1]`; the point
/// is drawn there in proportion to the scratch's width, `sqrt(1 - (s/l)^2)`: the scratch's
/// covered area, when the footprint holds it across. Where that span is empty (the scratch
/// nearest to the hit is not the one the footprint holds) it is the whole scratch's.
fn lean_place(ctx: &ShadingContext, sc: &Scratch, along: Along) -> f64 {
    let d = sc.direction;
    let rel = ctx.uv.as_dvec2() - sc.centre;
    let (a, b) = (rel.dot(d) / sc.half_length, d.perp_dot(rel) / sc.half_width);
    let u = match along {
        Along::Footprint(u) if a * a + b * b > 1.0 => u,
        _ => return a,
    };
    let (dx, dy) = ctx.footprint_uv();
    let (dx, dy) = (dx.as_dvec2(), dy.as_dvec2());
    let offset = ctx.pixel.map_or(DVec2::ZERO, |h| h.offset.as_dvec2());
    let centre = a - (offset.x * dx + offset.y * dy).dot(d) / sc.half_length;
    let e = 0.5 * (dx.dot(d).abs() + dy.dot(d).abs()) / sc.half_length;
    if e.is_nan() || e <= 0.0 {
        return a; // no footprint (no ray differentials): the hit's own place
    }
    let (lo, hi) = match ((centre - e).max(-1.0), (centre + e).min(1.0)) {
        (lo, hi) if lo < hi => (lo, hi),
        // The footprint misses the scratch found nearest to the hit (it holds another of the
        // layer's): a point of the whole scratch.
        _ => (-1.0, 1.0),
    };
    place_by_width(lo, hi, u)
}

/// `s/l` in `[lo, hi]` (within `[-1, 1]`) with density in proportion to the scratch's width
/// there, `sqrt(1 - (s/l)^2)`, for `u` uniform in `[0, 1]`: with `s/l = sin phi` the area up
/// to `phi` is `G(phi) = phi + sin(2 phi) / 2` ([`area_up_to`]), inverted.
pub(super) fn place_by_width(lo: f64, hi: f64, u: f32) -> f64 {
    let g = |x: f64| {
        if x.abs() >= 1.0 {
            std::f64::consts::FRAC_PI_2.copysign(x)
        } else {
            area_up_to(x.asin())
        }
    };
    let (g0, g1) = (g(lo), g(hi));
    area_inverse(g0 + u as f64 * (g1 - g0)).sin()
}

/// `G(phi) = phi + sin(2 phi) / 2`, the area of a unit semicircle's part `s/l < sin phi`
/// (times 2), increasing from `-pi/2` to `pi/2` over `[-pi/2, pi/2]`; `G' = 2 cos^2 phi`.
pub(super) fn area_up_to(phi: f64) -> f64 {
    phi + 0.5 * (2.0 * phi).sin()
}

/// `G^-1(g)` ([`area_up_to`]) for `g` in `[-pi/2, pi/2]`: a table of 256 intervals read
/// linearly, then Newton's method kept within the table's interval (bisection where a step
/// would leave it) to a residual of `1e-10`: one step where `cos phi > 0.1`, more at the
/// ends, where `G' = 2 cos^2 phi` vanishes.
pub(super) fn area_inverse(g: f64) -> f64 {
    use std::f64::consts::{FRAC_PI_2, PI};
    const N: usize = 256;
    static TABLE: std::sync::LazyLock<[f64; N + 1]> = std::sync::LazyLock::new(|| {
        std::array::from_fn(|i| {
            let target = -FRAC_PI_2 + PI * i as f64 / N as f64;
            // Bisection, once per table entry.
            let (mut a, mut b) = (-FRAC_PI_2, FRAC_PI_2);
            for _ in 0..60 {
                let mid = 0.5 * (a + b);
                if area_up_to(mid) < target {
                    a = mid;
                } else {
                    b = mid;
                }
            }
            0.5 * (a + b)
        })
    });
    let x = ((g + FRAC_PI_2) / PI * N as f64).clamp(0.0, N as f64);
    let i = (x as usize).min(N - 1);
    let (mut a, mut b) = (TABLE[i], TABLE[i + 1]);
    let mut phi = a + (x - i as f64) * (b - a);
    for _ in 0..24 {
        let (sin2, cos2) = (2.0 * phi).sin_cos();
        let r = phi + 0.5 * sin2 - g;
        if r.abs() < 1e-10 {
            break;
        }
        if r < 0.0 {
            a = phi;
        } else {
            b = phi;
        }
        let next = phi - r / (1.0 + cos2);
        phi = if next > a && next < b {
            next
        } else {
            0.5 * (a + b)
        };
    }
    phi
}
