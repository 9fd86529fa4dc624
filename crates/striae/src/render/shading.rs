//! What a material sees at a hit: the [`ShadingContext`] (texture coordinates and their pixel
//! footprint, surface derivatives, shading frame, a spare random number), and the ray
//! differentials that produce the footprint (pbrt-v4 section 10.1, after Igehy 1999).
//!
//! Ray differentials. Camera rays carry exact differentials (one pixel step in x and y). At a
//! hit, the offset rays are intersected with the tangent plane (`ng` through `p`) to give
//! `dP/dx`, `dP/dy`, and `du/dx`, ... follow by least squares against `dP/du`, `dP/dv`
//! (pbrt's `ComputeDifferentials`). Spawned rays carry differentials as follows:
//! * delta reflection / refraction: the two offset rays start at `p + dP/dx`, `p + dP/dy` and
//!   their directions are reflected / refracted about the **shading normal at their own
//!   start**, the hit's normal plus the change of the surface's normal field from `p` to
//!   `p + dP/dx` (`Geometry::shading_normal_steps`: `dP/dx / r` on a sphere, the derivative of
//!   the interpolated vertex normals on a mesh, a per-triangle matrix computed at load time),
//!   its part along the normal dropped (it only changes the length: the offset normal is then
//!   unit to second order in the step). This is Igehy's (1999) and pbrt-v4's `dn/dx`
//!   term, with the offset ray then mirrored or refracted exactly about its own normal, so a
//!   curved mirror or lens widens or narrows the beam as it should; flat surfaces keep the
//!   hit's normal. Whether a bounce reflects or refracts is decided once, by the central ray;
//!   an offset ray totally reflected where the central one refracts is mirrored.
//! * any non-delta bounce: the offset rays start at `p + dP/dx`, `p + dP/dy` and run
//!   **parallel** to the new direction, so the footprint keeps the width it had at this hit
//!   (a footprint-preserving approximation; pbrt-v3 drops differentials there, pbrt-v4
//!   re-derives them from the camera).

// `!(x > 0.0)` is meant: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use crate::math::{Frame, RayDifferential, Vec2, Vec3};
use crate::render::geometry::SurfaceHit;

/// Everything a material may use to build its BSDF at one hit. New fields may be added (the
/// scratched material filters its layers over the footprint, [`ShadingContext::footprint_uv`],
/// METHOD.md section 6).
#[derive(Clone, Copy, Debug)]
pub struct ShadingContext {
    /// World position.
    pub p: Vec3,
    /// Texture coordinates.
    pub uv: Vec2,
    /// The differentials of the ray that arrived (`None`: it carries none). The footprint they
    /// give ([`ShadingContext::footprint_uv`]) is worked out on demand: the scratched material
    /// needs it only at a pixel's first sample on a surface, the others share that sample's.
    pub rd: Option<RayDifferential>,
    /// Position derivatives, as in `SurfaceHit`.
    pub dpdu: Vec3,
    pub dpdv: Vec3,
    /// The shading frame the BSDF works in (`n` = shading normal as the integrator uses it,
    /// `s` along `dP/du` made orthogonal to it).
    pub frame: Frame,
    /// Unit geometric normal as the shape defines it.
    pub ng: Vec3,
    /// A uniform random number in `[0, 1)` from the pixel's sample stream, for stochastic
    /// choices a material makes once per hit (e.g. which scratch layer where several cross).
    pub u_layer: f32,
    /// The direction toward the viewer (`-ray.d`, world, unit). Scratched glass skips its
    /// layer queries for rays arriving from inside.
    pub wo: Vec3,
    /// For a hit of a camera path that carries differentials and has only bounced specularly
    /// so far (the camera ray's first hit included): which chain of delta bounces and which
    /// shape, and where in the pixel the ray went, so that a material can filter over the
    /// footprint of the whole pixel once and share it among the pixel's samples
    /// (`layers::CoverageCache::of_pixel`; the render loop starts the cache's pixel).
    pub pixel: Option<PixelHit>,
    /// How far below the surface (world units) the arriving ray began, for a ray that went on
    /// from below the surface rather than from a hit ([`crate::render::bsdf::BsdfSample::from`]);
    /// infinite for every other ray. Scratched glass seen from inside looks for grooves the ray
    /// met beside their openings no deeper than this.
    pub origin_depth: f32,
}

impl ShadingContext {
    /// Change of `uv` for one pixel step in x and in y (the pixel footprint in texture space):
    /// the ray differentials met with the tangent plane ([`footprint`]); zero without them.
    #[inline]
    pub fn footprint_uv(&self) -> (Vec2, Vec2) {
        match &self.rd {
            Some(rd) => {
                let (dpdx, dpdy) = footprint_dp_at(self.p, self.ng, rd);
                footprint_uv_at(self.dpdu, self.dpdv, dpdx, dpdy)
            }
            None => (Vec2::ZERO, Vec2::ZERO),
        }
    }
}

/// A hit reached from a pixel by delta bounces only ([`ShadingContext::pixel`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PixelHit {
    /// The shape hit.
    pub shape: u32,
    /// Names the chain of delta bounces that led here: 0 for the camera ray's first hit, else
    /// a hash of the shapes met and whether each bounce reflected or refracted
    /// ([`PixelHit::chain_after`]). The pixel's samples that took the same chain see the same
    /// surface through the same lenses and mirrors.
    pub chain: u64,
    /// The film position of the ray minus the pixel's centre, in pixels (each component in
    /// `[-1/2, 1/2]`): the texture point of the pixel centre's ray along the same chain is
    /// about `uv - offset.x duvdx - offset.y duvdy` (the differentials are carried linearly).
    pub offset: Vec2,
}

impl PixelHit {
    /// The chain after a delta bounce off `shape` that reflected or (`transmitted`) refracted.
    #[inline]
    pub fn chain_after(chain: u64, shape: u32, transmitted: bool) -> u64 {
        crate::hash::splitmix64(chain ^ (((shape as u64) << 1 | transmitted as u64) + 1))
    }
}

/// Bend the shading normal `ns` toward the geometric normal `ng` (same hemisphere) so that
/// `wo` lies on the same side of it as of `ng`, with a small margin. Returns `ns` unchanged in
/// the usual case.
#[inline]
pub fn guard_shading_normal(ns: Vec3, ng: Vec3, wo: Vec3) -> Vec3 {
    const MARGIN: f32 = 1e-3;
    let g = wo.dot(ng);
    let side = if g >= 0.0 { 1.0 } else { -1.0 };
    let c = wo.dot(ns) * side;
    if c >= MARGIN {
        return ns;
    }
    let t = (MARGIN - c) / g.abs().max(1e-6);
    (ns + t * ng).normalize_or(ng)
}

/// The shading context at `hit` in `frame` (the options as `material::HitView`'s; the pixel is
/// kept only with differentials).
#[inline(always)]
pub fn hit_context(
    hit: &SurfaceHit,
    rd: Option<&RayDifferential>,
    frame: Frame,
    wo_world: Vec3,
    u_layer: f32,
    pixel: Option<PixelHit>,
) -> ShadingContext {
    ShadingContext {
        p: hit.p,
        uv: hit.uv,
        rd: rd.copied(),
        dpdu: hit.dpdu,
        dpdv: hit.dpdv,
        frame,
        ng: hit.ng,
        u_layer,
        wo: wo_world,
        pixel: pixel.filter(|_| rd.is_some()),
        origin_depth: f32::INFINITY,
    }
}

/// The shading frame at `hit` seen from `wo_world` for a material that transmits or not
/// (`Material::has_transmission`): the shading normal and `dP/du`, the normal flipped to
/// `wo`'s side for opaque materials (two-sided), then guarded against `wo` falling behind it
/// ([`guard_shading_normal`]). Worked out before the material's BSDF, which is then built
/// once, in its final frame.
#[inline(always)]
pub fn shading_frame(hit: &SurfaceHit, wo_world: Vec3, transmits: bool) -> Frame {
    shading_frame_of(hit.ng, hit.ns, hit.dpdu, wo_world, transmits)
}

/// [`shading_frame`] of a hit's geometric normal `hit_ng`, shading normal `hit_ns` and `dP/du`.
#[inline(always)]
pub fn shading_frame_of(
    hit_ng: Vec3,
    hit_ns: Vec3,
    dpdu: Vec3,
    wo_world: Vec3,
    transmits: bool,
) -> Frame {
    let (mut ng, mut ns) = (hit_ng, hit_ns);
    if !transmits && wo_world.dot(ng) < 0.0 {
        // Opaque surfaces are two-sided: shade on wo's side.
        ng = -ng;
        ns = -ns;
    }
    let guarded = guard_shading_normal(ns, ng, wo_world);
    // `hit_ns` itself where the guard left it equal (a zero's sign aside), as before.
    let n = if guarded != hit_ns { guarded } else { hit_ns };
    Frame::from_normal_tangent(n, dpdu)
}

/// `dP/dx`, `dP/dy`, `du/dx`, `dv/dx`, `du/dy`, `dv/dy` at a hit from the ray's differentials
/// (pbrt-v4 `SurfaceInteraction::ComputeDifferentials`). Degenerate cases give zeros.
pub fn footprint(hit: &SurfaceHit, rd: &RayDifferential) -> (Vec3, Vec3, Vec2, Vec2) {
    let (dpdx, dpdy) = footprint_dp(hit, rd);
    let (duvdx, duvdy) = footprint_uv(hit, dpdx, dpdy);
    (dpdx, dpdy, duvdx, duvdy)
}

/// The `dP/dx`, `dP/dy` part of [`footprint`]: the offset rays met with the tangent plane.
#[inline]
pub fn footprint_dp(hit: &SurfaceHit, rd: &RayDifferential) -> (Vec3, Vec3) {
    footprint_dp_at(hit.p, hit.ng, rd)
}

/// [`footprint_dp`] at the point `p` with the unit geometric normal `n`.
#[inline]
fn footprint_dp_at(p: Vec3, n: Vec3, rd: &RayDifferential) -> (Vec3, Vec3) {
    let plane = n.dot(p);
    let offset = |o: Vec3, d: Vec3| -> Vec3 {
        let denom = n.dot(d);
        if denom == 0.0 {
            return Vec3::ZERO;
        }
        let t = (plane - n.dot(o)) / denom;
        let dp = o + t * d - p;
        if dp.is_finite() {
            dp
        } else {
            Vec3::ZERO
        }
    };
    (offset(rd.rx_o, rd.rx_d), offset(rd.ry_o, rd.ry_d))
}

/// The `du/dx`, `dv/dx`, `du/dy`, `dv/dy` part of [`footprint`] from `dP/dx`, `dP/dy`.
#[inline]
pub fn footprint_uv(hit: &SurfaceHit, dpdx: Vec3, dpdy: Vec3) -> (Vec2, Vec2) {
    footprint_uv_at(hit.dpdu, hit.dpdv, dpdx, dpdy)
}

/// [`footprint_uv`] with the position derivatives `a = dP/du`, `b = dP/dv`.
#[inline]
fn footprint_uv_at(a: Vec3, b: Vec3, dpdx: Vec3, dpdy: Vec3) -> (Vec2, Vec2) {
    // Least squares for [dpdu dpdv] (du, dv)^T = dp.
    let (aa, ab, bb) = (a.dot(a), a.dot(b), b.dot(b));
    let det = aa * bb - ab * ab;
    let solve = |dp: Vec3| -> Vec2 {
        if !(det.abs() > 1e-20) || !det.is_finite() {
            return Vec2::ZERO;
        }
        let (ra, rb) = (a.dot(dp), b.dot(dp));
        let du = (bb * ra - ab * rb) / det;
        let dv = (aa * rb - ab * ra) / det;
        let clamp = |x: f32| {
            if x.is_finite() {
                x.clamp(-1e8, 1e8)
            } else {
                0.0
            }
        };
        Vec2::new(clamp(du), clamp(dv))
    };
    (solve(dpdx), solve(dpdy))
}

/// Refract unit direction `d` (travelling toward the surface) through the plane with unit
/// normal `n` facing against `d`, with relative index `eta = n_incident / n_transmitted`.
/// `None` under total internal reflection.
#[inline]
pub fn refract_dir(d: Vec3, n: Vec3, eta: f32) -> Option<Vec3> {
    let cos_i = -d.dot(n);
    let sin2_t = eta * eta * (1.0 - cos_i * cos_i).max(0.0);
    if sin2_t >= 1.0 {
        return None;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    Some(eta * d + (eta * cos_i - cos_t) * n)
}

/// Differentials of a ray spawned at `p` in direction `wi` (world, unit) from a hit reached by
/// a ray with direction `d_in` and differentials `rd` (see the module notes). `delta` selects
/// the specular rule, `ns` is the shading normal of the bounce, `offset_normals` the shading
/// normals at `p + dpdx` and `p + dpdy` on the same side as `ns` (`None`: `ns` for both, a
/// locally flat surface) and, for refraction, `eta = n_incident / n_transmitted` along the
/// path's direction of travel.
#[allow(clippy::too_many_arguments)]
// Always inlined: LLVM's own choice depends on unrelated code in the loop, and out of line
// (compiled for baseline x86-64, the loop's registers spilled at the call) it costs the
// close-up 6 %.
#[inline(always)]
pub fn spawn_differentials(
    p: Vec3,
    dpdx: Vec3,
    dpdy: Vec3,
    d_in: Vec3,
    rd: &RayDifferential,
    ns: Vec3,
    offset_normals: Option<(Vec3, Vec3)>,
    wi: Vec3,
    delta: bool,
    eta: f32,
) -> RayDifferential {
    let rx_o = p + dpdx;
    let ry_o = p + dpdy;
    if !delta {
        return RayDifferential {
            rx_o,
            rx_d: wi,
            ry_o,
            ry_d: wi,
        };
    }
    let reflection = (wi.dot(ns) > 0.0) == ((-d_in).dot(ns) > 0.0);
    // The normals facing the incoming ray.
    let side = if d_in.dot(ns) < 0.0 { 1.0 } else { -1.0 };
    let (nx, ny) = offset_normals.unwrap_or((ns, ns));
    // Mirroring and refracting a unit direction about a unit normal give a unit direction up
    // to rounding (a relative 1e-7 per bounce, harmless to the footprint), so neither is
    // normalised again; a non-finite result falls back to `wi`.
    RayDifferential {
        rx_o,
        rx_d: bend_differential(rd.rx_d, side * nx, wi, reflection, eta),
        ry_o,
        ry_d: bend_differential(rd.ry_d, side * ny, wi, reflection, eta),
    }
}

/// An offset ray's direction `d` mirrored (`reflection`) or refracted about the unit normal
/// `n` facing it (see [`spawn_differentials`]); a non-finite result falls back to `wi`.
#[inline(always)]
fn bend_differential(d: Vec3, n: Vec3, wi: Vec3, reflection: bool, eta: f32) -> Vec3 {
    let finite_or_wi = |d: Vec3| if d.is_finite() { d } else { wi };
    let mirror = |d: Vec3| finite_or_wi(d - 2.0 * d.dot(n) * n);
    if reflection {
        mirror(d)
    } else {
        // The mirror only under total internal reflection (computed only then).
        match refract_dir(d, n, eta) {
            Some(t) => finite_or_wi(t),
            None => mirror(d),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plane_hit() -> SurfaceHit {
        // The plane z = 0 parametrised by u = x / 2, v = y / 2 (dP/du = 2 x, dP/dv = 2 y).
        SurfaceHit {
            t: 1.0,
            p: Vec3::ZERO,
            ng: Vec3::Z,
            ns: Vec3::Z,
            uv: Vec2::new(0.5, 0.5),
            dpdu: Vec3::new(2.0, 0.0, 0.0),
            dpdv: Vec3::new(0.0, 2.0, 0.0),
            shape: 0,
            prim: 0,
        }
    }

    #[test]
    fn footprint_of_a_head_on_plane() {
        // Offset rays parallel to the central one, 0.1 apart in x and 0.2 in y.
        let rd = RayDifferential {
            rx_o: Vec3::new(0.1, 0.0, 1.0),
            rx_d: -Vec3::Z,
            ry_o: Vec3::new(0.0, 0.2, 1.0),
            ry_d: -Vec3::Z,
        };
        let (dpdx, dpdy, duvdx, duvdy) = footprint(&plane_hit(), &rd);
        assert!((dpdx - Vec3::new(0.1, 0.0, 0.0)).length() < 1e-6);
        assert!((dpdy - Vec3::new(0.0, 0.2, 0.0)).length() < 1e-6);
        assert!((duvdx - Vec2::new(0.05, 0.0)).length() < 1e-6);
        assert!((duvdy - Vec2::new(0.0, 0.1)).length() < 1e-6);
    }

    #[test]
    fn refraction_obeys_snell_and_differentials_bend() {
        let d = Vec3::new(0.6, 0.0, -0.8);
        let t = refract_dir(d, Vec3::Z, 1.0 / 1.5).unwrap();
        assert!((t.length() - 1.0).abs() < 1e-5);
        assert!(
            (t.x - 0.6 / 1.5).abs() < 1e-5,
            "sin theta_t = sin theta_i / 1.5"
        );
        // Total internal reflection from inside at a grazing angle.
        assert!(refract_dir(Vec3::new(0.9, 0.0, -0.435_889_9), Vec3::Z, 1.5).is_none());
        // Differentials of a refracted parallel beam stay parallel to the refracted ray.
        let rd = RayDifferential {
            rx_o: Vec3::X,
            rx_d: d,
            ry_o: Vec3::Y,
            ry_d: d,
        };
        let out = spawn_differentials(
            Vec3::ZERO,
            Vec3::X * 0.1,
            Vec3::Y * 0.1,
            d,
            &rd,
            Vec3::Z,
            None,
            t,
            true,
            1.0 / 1.5,
        );
        assert!((out.rx_d - t).length() < 1e-5);
        // A diverging beam keeps diverging after refraction, less than before (entering glass).
        let dx = (d + Vec3::new(0.01, 0.0, 0.0)).normalize();
        let rd = RayDifferential {
            rx_o: Vec3::ZERO,
            rx_d: dx,
            ry_o: Vec3::ZERO,
            ry_d: d,
        };
        let out = spawn_differentials(
            Vec3::ZERO,
            Vec3::ZERO,
            Vec3::ZERO,
            d,
            &rd,
            Vec3::Z,
            None,
            t,
            true,
            1.0 / 1.5,
        );
        let before = (dx - d).length();
        let after = (out.rx_d - t).length();
        assert!(after > 0.0 && after < before, "{before} {after}");
        // Reflection mirrors the offset directions.
        let r = Vec3::new(0.6, 0.0, 0.8);
        let out = spawn_differentials(
            Vec3::ZERO,
            Vec3::ZERO,
            Vec3::ZERO,
            d,
            &rd,
            Vec3::Z,
            None,
            r,
            true,
            1.0,
        );
        assert!((out.rx_d - Vec3::new(dx.x, dx.y, -dx.z)).length() < 1e-6);
    }
}
