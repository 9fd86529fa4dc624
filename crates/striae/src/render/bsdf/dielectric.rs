//! Dielectric interfaces: smooth (exact Fresnel, reflect or refract chosen with probability
//! `F`; Mitsuba 3 `dielectric`, pbrt-v4 `DielectricBxDF`) and rough GGX (Walter et al. 2007
//! eqs. 20-21, 38-41; visible-normal sampling, Heitz 2018).
//!
//! `eta = n_inside / n_outside` (1.5 for glass in air); the outside is the side the shading
//! normal (`+z`) points to. Refraction scales radiance by `1 / eta_t^2` with `eta_t` the
//! relative index `n(wi side) / n(wo side)` (radiance transport, see the module `bsdf`).

use super::BsdfSample;
use crate::math::{reflect, reflect_z, Rgb, Vec2, Vec3};
use crate::optics::fresnel_f32;
use crate::optics::microfacet::{visible_azimuth, Ggx};

/// Refract `wo` through the (micro)normal `m` given the signed cosine of the transmitted
/// direction `cos_t` (sign opposite to `wo . m`) and `eta_ti = n(wo side) / n(wi side)`
/// (Mitsuba 3's `refract`). Both directions point away from the surface.
#[inline(always)]
pub(super) fn refract(wo: Vec3, m: Vec3, cos_t: f32, eta_ti: f32) -> Vec3 {
    m * (wo.dot(m) * eta_ti + cos_t) - wo * eta_ti
}

/// A smooth dielectric interface: a delta reflection and a delta transmission lobe.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Dielectric {
    /// `n_inside / n_outside`, `>= 1` for the usual case (validated in `material`).
    pub eta: f32,
}

impl Dielectric {
    pub fn new(eta: f32) -> Self {
        Dielectric { eta }
    }

    /// Choose reflection with probability `F(wo.z)` (exact Fresnel), else refraction; both
    /// lobes then carry weight 1 (times `1 / eta_t^2` for refraction, radiance transport).
    #[inline]
    pub fn sample(&self, wo: Vec3, u_lobe: f32) -> Option<BsdfSample> {
        let (r, cos_t, eta_it) = fresnel_f32::dielectric(wo.z, self.eta);
        if u_lobe < r || r >= 1.0 {
            return Some(mirror_sample(wo, r));
        }
        Some(refraction_sample(wo, cos_t, eta_it, 1.0 - r))
    }
}

/// The smooth interface's mirror reflection of `wo`, chosen with probability `pdf` (weight 1).
#[inline(always)]
pub(super) fn mirror_sample(wo: Vec3, pdf: f32) -> BsdfSample {
    BsdfSample {
        wi: reflect_z(wo),
        weight: Rgb::ONE,
        pdf,
        delta: true,
        eta: 1.0,
        from: None,
    }
}

/// The smooth interface's refraction of `wo` (`cos_t`, `eta_it` from
/// [`fresnel_f32::dielectric`]), chosen with probability `pdf`: weight `1 / eta_it^2`, the
/// radiance factor.
#[inline(always)]
pub(super) fn refraction_sample(wo: Vec3, cos_t: f32, eta_it: f32, pdf: f32) -> BsdfSample {
    let eta_ti = 1.0 / eta_it;
    BsdfSample {
        wi: Vec3::new(-eta_ti * wo.x, -eta_ti * wo.y, cos_t),
        weight: Rgb::splat(eta_ti * eta_ti),
        pdf,
        delta: true,
        eta: eta_it,
        from: None,
    }
}

/// A rough GGX dielectric interface (Walter et al. 2007).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RoughDielectric {
    /// `n_inside / n_outside`.
    pub eta: f32,
    pub distribution: Ggx,
}

/// The generalised half vector of `(wo, wi)` (Walter eq. 16), in the upper hemisphere, and
/// `eta_p = n(wi side) / n(wo side)` (1 for reflection). `None` for degenerate pairs and for
/// pairs whose half vector is back-facing to either direction (no microfacet connects them).
#[inline(always)]
pub(super) fn half_vector(eta: f32, wo: Vec3, wi: Vec3) -> Option<(Vec3, f32, bool)> {
    let reflect = wo.z * wi.z > 0.0;
    let eta_p = if reflect {
        1.0
    } else if wo.z > 0.0 {
        eta
    } else {
        1.0 / eta
    };
    let m = wo + wi * eta_p;
    let len2 = m.length_squared();
    let m = m / len2.sqrt();
    let m = if m.z < 0.0 { -m } else { m };
    let connects = (wo.z != 0.0)
        & (wi.z != 0.0)
        & (len2 > 1e-14)
        & !(m.dot(wi) * wi.z <= 0.0)
        & !(m.dot(wo) * wo.z <= 0.0);
    connects.then_some((m, eta_p, reflect))
}

/// [`half_vector`]'s pair, and whether it connects the directions: the lane vertex's SIMD
/// loop computes with the placeholder where it does not, and selects its result away.
#[inline(always)]
fn half_vector_or_placeholder(eta: f32, wo: Vec3, wi: Vec3) -> ((Vec3, f32, bool), bool) {
    let h = half_vector(eta, wo, wi);
    (h.unwrap_or((Vec3::Z, 1.0, true)), h.is_some())
}

impl RoughDielectric {
    pub fn new(eta: f32, alpha: f32) -> Self {
        RoughDielectric {
            eta,
            distribution: Ggx::isotropic(alpha),
        }
    }

    /// Walter eq. 20 (reflection) and eq. 21 (transmission, divided by `eta_p^2` for radiance).
    /// (Inlined always, as [`Self::pdf`] and [`Self::sample_at`]: the lane vertex's SIMD loop
    /// runs them, and a call keeps it scalar.)
    #[inline(always)]
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Rgb {
        let ((m, eta_p, reflect), connects) = half_vector_or_placeholder(self.eta, wo, wi);
        let (wo_m, wi_m) = (wo.dot(m), wi.dot(m));
        let f = fresnel_f32::dielectric(wo_m, self.eta).0;
        let dg = self.distribution.d(m) * self.distribution.g(wo, wi, m);
        let reflected = dg * f / (4.0 * (wo.z * wi.z).abs());
        let denom = (wi_m + wo_m / eta_p).powi(2);
        let transmitted =
            dg * (1.0 - f) * (wi_m * wo_m).abs() / ((wi.z * wo.z).abs() * denom) / (eta_p * eta_p);
        let v = if reflect { reflected } else { transmitted };
        if connects {
            Rgb::splat(v)
        } else {
            Rgb::ZERO
        }
    }

    /// Visible-normal density times the Jacobian of the reflection (Walter eq. 14) or
    /// refraction (eq. 17) map, times the probability of choosing that lobe (`F` or `1 - F`).
    #[inline(always)]
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        let ((m, eta_p, reflect), connects) = half_vector_or_placeholder(self.eta, wo, wi);
        let (wo_m, wi_m) = (wo.dot(m), wi.dot(m));
        let f = fresnel_f32::dielectric(wo_m, self.eta).0;
        let v = wo * wo.z.signum();
        let pdf_m = self.distribution.pdf_visible(v, m);
        let reflected = f * pdf_m / (4.0 * wo_m.abs());
        let denom = (wi_m + wo_m / eta_p).powi(2);
        let transmitted = (1.0 - f) * pdf_m * wi_m.abs() / denom;
        match (connects, reflect) {
            (false, _) => 0.0,
            (true, true) => reflected,
            (true, false) => transmitted,
        }
    }

    /// `(eval, pdf)` sharing the half vector, Fresnel term and `D` (what light sampling with
    /// MIS needs).
    #[inline]
    pub fn eval_pdf(&self, wo: Vec3, wi: Vec3) -> (Rgb, f32) {
        let Some((m, eta_p, reflect)) = half_vector(self.eta, wo, wi) else {
            return (Rgb::ZERO, 0.0);
        };
        let (wo_m, wi_m) = (wo.dot(m), wi.dot(m));
        let f = fresnel_f32::dielectric(wo_m, self.eta).0;
        let d = self.distribution.d(m);
        let g1_o = self.distribution.g1(wo, m);
        let g = g1_o * self.distribution.g1(wi, m);
        // pdf_visible(v, m) with v = wo flipped to the upper side: G1(wo) |wo.m| D / |wo.z|.
        let pdf_m = g1_o * wo_m.abs() * d / wo.z.abs();
        if reflect {
            let v = d * g * f / (4.0 * (wo.z * wi.z).abs());
            (Rgb::splat(v), f * pdf_m / (4.0 * wo_m.abs()))
        } else {
            let denom = (wi_m + wo_m / eta_p).powi(2);
            let v = d * g * (1.0 - f) * (wi_m * wo_m).abs()
                / ((wi.z * wo.z).abs() * denom)
                / (eta_p * eta_p);
            (Rgb::splat(v), (1.0 - f) * pdf_m * wi_m.abs() / denom)
        }
    }

    /// Sample a visible microfacet normal from `wo`'s side, then reflect (probability `F`) or
    /// refract through it. Weight `G1(wi)` (separable Smith), `/ eta_p^2` for refraction.
    #[inline]
    pub fn sample(&self, wo: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        self.sample_at(wo, u_lobe, u.x, visible_azimuth(u.y))
    }

    /// [`Self::sample`] with the visible normal's azimuth given ([`Ggx::sample_visible_at`]).
    #[inline(always)]
    pub fn sample_at(
        &self,
        wo: Vec3,
        u_lobe: f32,
        u_x: f32,
        azimuth: (f32, f32),
    ) -> Option<BsdfSample> {
        let v = wo * wo.z.signum();
        let m = self.distribution.sample_visible_at(v, u_x, azimuth);
        let pdf_m = self.distribution.pdf_visible(v, m);
        let wo_m = wo.dot(m);
        let (f, cos_t, eta_it) = fresnel_f32::dielectric(wo_m, self.eta);
        // Both lobes, then the chosen one (`F`, or `1 - F`).
        let wi_r = reflect(wo, m);
        let pdf_r = f * pdf_m / (4.0 * wo_m.abs());
        let g1_r = self.distribution.g1(wi_r, m);
        let reflected = !(wi_r.z * wo.z <= 0.0) & (pdf_r > 0.0) & !(g1_r <= 0.0);
        let eta_p = eta_it;
        let wi_t = refract(wo, m, cos_t, 1.0 / eta_p).normalize();
        let wi_m = wi_t.dot(m);
        let denom = (wi_m + wo_m / eta_p).powi(2);
        let pdf_t = (1.0 - f) * pdf_m * wi_m.abs() / denom;
        let g1_t = self.distribution.g1(wi_t, m);
        let transmitted =
            !(wi_t.z * wo.z >= 0.0) & wi_t.is_finite() & (pdf_t > 0.0) & !(g1_t <= 0.0);
        let reflects = u_lobe < f || f >= 1.0;
        let sample = if reflects {
            BsdfSample {
                wi: wi_r,
                weight: Rgb::splat(g1_r),
                pdf: pdf_r,
                delta: false,
                eta: 1.0,
                from: None,
            }
        } else {
            BsdfSample {
                wi: wi_t,
                weight: Rgb::splat(g1_t / (eta_p * eta_p)),
                pdf: pdf_t,
                delta: false,
                eta: eta_p,
                from: None,
            }
        };
        let valid = (wo.z != 0.0) & (pdf_m > 0.0) & if reflects { reflected } else { transmitted };
        valid.then_some(sample)
    }
}
