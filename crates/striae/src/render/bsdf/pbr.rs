//! glTF 2.0's metallic-roughness BSDF (glTF 2.0 specification, Appendix B, "BRDF
//! Implementation"), with KHR_materials_transmission, KHR_materials_ior and
//! KHR_materials_anisotropy:
//!
//! ```text
//! f = mix(dielectric_brdf, metal_brdf, metallic)
//! metal_brdf      = specular_brdf(alpha) * (base + (1 - base) (1 - |wo.m|)^5)
//! dielectric_brdf = fresnel_mix(ior, base = mix(diffuse, specular_btdf(alpha) * base,
//!                                               transmission),
//!                               layer = specular_brdf(alpha))
//! ```
//!
//! `specular_brdf` and `specular_btdf` are the GGX reflection and refraction of
//! [`RoughDielectric`] (Walter et al. 2007, separable Smith `G`, visible-normal sampling), and
//! at `alpha = 0` the delta lobes of [`Dielectric`]; the anisotropic GGX (`alpha_x` along the
//! frame's `s`, which the material turns to the anisotropy direction) is
//! KHR_materials_anisotropy's `alpha_t = mix(alpha, 1, strength^2)`, `alpha_b = alpha`.
//!
//! Departures from Appendix B, each to keep the model energy-conserving or equal to the
//! existing dielectric:
//! * the dielectric Fresnel term is the exact one ([`fresnel_f32::dielectric`] at `wo.m`), not
//!   Schlick's with `f0 = ((ior - 1) / (ior + 1))^2`; so with `metallic = 0, transmission = 1`
//!   the BSDF is [`RoughDielectric`] (or [`Dielectric`]) with the refracted part tinted by
//!   `base_color`. The metal's Fresnel stays Schlick's with `f0 = base_color`, as the spec has.
//! * the diffuse lobe is weighted by `(1 - F(wo.z)) (1 - F(wi.z))` (Fresnel at the macro
//!   normal, on both sides: reciprocal) rather than by `1 - F(wo.m)` at the half vector of `wo`
//!   and `wi`, which lets the albedo exceed 1 at grazing `wo` (the specular layer reflects
//!   `F(wo.z)` of the light, the diffuse one was still given nearly all of it).
//! * seen from inside (`wo.z < 0`, only for a material that transmits) the surface is the
//!   tinted dielectric alone: the metal and diffuse parts are taken to face outward.
//!
//! Sampling. A lobe is chosen from the weights at `wo`: the diffuse lobe with probability
//! `p_d = w_d / (w_d + w_m)`, `w_d = (1 - metallic)(1 - transmission)(1 - F(wo.z))
//! mean(base)`, `w_m = metallic mean(F_schlick(wo.z)) + (1 - metallic)(F(wo.z) + transmission
//! (1 - F(wo.z)))`; else a visible microfacet normal `m` is drawn and reflected with
//! probability `r / (r + t)`, `r = metallic mean(F_schlick(wo.m)) + (1 - metallic) F(wo.m)`,
//! `t = (1 - metallic) transmission (1 - F(wo.m))`, refracted otherwise (for `metallic = 0,
//! transmission = 1`: `F(wo.m)`, [`RoughDielectric`]'s choice). `pdf` is the whole mixture's
//! density, and a sample's weight `f |cos| / pdf`, so MIS stays correct. At `alpha = 0` the
//! reflection and refraction are deltas ([`BsdfSample::delta`], `pdf` the discrete
//! probability) beside the diffuse lobe, whose density alone `pdf` and `eval` report.

// `!(x > 0.0)` is meant: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use super::dielectric::{half_vector, mirror_sample, refract, refraction_sample};
use super::BsdfSample;
use crate::math::{reflect, Rgb, Vec2, Vec3, INV_PI};
use crate::optics::fresnel_f32;
use crate::optics::microfacet::Ggx;
use crate::sampling::{cosine_hemisphere_pdf, square_to_cosine_hemisphere};

/// The glTF metallic-roughness BSDF at one point (textures looked up).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pbr {
    /// Linear base colour in `[0, 1]`.
    pub base_color: Rgb,
    /// `[0, 1]`.
    pub metallic: f32,
    /// `[0, 1]`.
    pub transmission: f32,
    /// `n_inside / n_outside` (glTF's `ior`, the outside vacuum), `>= 1`.
    pub eta: f32,
    /// GGX with `alpha_x = alpha_t`, `alpha_y = alpha_b` (ignored when `smooth`).
    pub distribution: Ggx,
    /// `alpha = 0`: delta reflection and refraction.
    pub smooth: bool,
    /// Whether the material transmits anywhere ([`super::Bsdf::has_transmission`]): fixed per
    /// material, so that the shading frame is chosen before the textures are read.
    pub transmits: bool,
}

/// How the lobes share the light at one `wo`.
#[derive(Clone, Copy, Debug)]
struct AtWo {
    metallic: f32,
    transmission: f32,
    /// Probability of sampling the diffuse lobe.
    p_diffuse: f32,
}

#[inline]
fn mean(c: Rgb) -> f32 {
    (c.x + c.y + c.z) * (1.0 / 3.0)
}

/// Schlick's Fresnel with `f0` (glTF's `conductor_fresnel`), at the cosine `c`.
#[inline]
fn schlick(f0: Rgb, c: f32) -> Rgb {
    let x = (1.0 - c.abs()).clamp(0.0, 1.0);
    let x2 = x * x;
    f0 + (Rgb::ONE - f0) * (x2 * x2 * x)
}

impl Pbr {
    /// A PBR BSDF; `alpha_t`, `alpha_b` are GGX alphas (0 and 0: smooth).
    pub fn new(
        base_color: Rgb,
        metallic: f32,
        transmission: f32,
        eta: f32,
        alpha_t: f32,
        alpha_b: f32,
        transmits: bool,
    ) -> Self {
        let smooth = !(alpha_t > 0.0 || alpha_b > 0.0);
        Pbr {
            base_color,
            metallic,
            transmission,
            eta,
            distribution: Ggx {
                alpha_x: alpha_t.max(Ggx::MIN_ALPHA),
                alpha_y: alpha_b.max(Ggx::MIN_ALPHA),
            },
            smooth,
            transmits,
        }
    }

    /// Whether every lobe is a delta (smooth, and no diffuse lobe).
    #[inline]
    pub fn is_delta(&self) -> bool {
        self.smooth
            && !((1.0 - self.metallic) * (1.0 - self.transmission) * mean(self.base_color) > 0.0)
    }

    /// The lobe weights at `wo`; `None` where the BSDF gives nothing (behind an opaque one).
    #[inline]
    fn at_wo(&self, wo: Vec3) -> Option<AtWo> {
        if wo.z > 0.0 {
            let (m, t) = (self.metallic, self.transmission);
            let fd = fresnel_f32::dielectric(wo.z, self.eta).0;
            let w_d = (1.0 - m) * (1.0 - t) * (1.0 - fd) * mean(self.base_color);
            let w_m = m * mean(schlick(self.base_color, wo.z)) + (1.0 - m) * (fd + t * (1.0 - fd));
            let sum = w_d + w_m;
            if !(sum > 0.0) {
                return None;
            }
            Some(AtWo {
                metallic: m,
                transmission: t,
                p_diffuse: w_d / sum,
            })
        } else if wo.z < 0.0 && self.transmits {
            Some(AtWo {
                metallic: 0.0,
                transmission: 1.0,
                p_diffuse: 0.0,
            })
        } else {
            None
        }
    }

    /// Probability of reflecting (not refracting) through a microfacet seen at `wo_m` with
    /// dielectric Fresnel `fd`.
    #[inline]
    fn reflect_prob(&self, a: &AtWo, wo_m: f32, fd: f32) -> f32 {
        if a.metallic == 0.0 && a.transmission == 1.0 {
            return fd;
        }
        let r = a.metallic * mean(schlick(self.base_color, wo_m)) + (1.0 - a.metallic) * fd;
        let t = (1.0 - a.metallic) * a.transmission * (1.0 - fd);
        if r + t > 0.0 {
            r / (r + t)
        } else {
            1.0
        }
    }

    /// The diffuse lobe, `(1 - m)(1 - t) base / pi (1 - F(wo.z)) (1 - F(wi.z))`, both outside.
    #[inline]
    fn diffuse(&self, a: &AtWo, wo: Vec3, wi: Vec3) -> Rgb {
        let k = (1.0 - a.metallic) * (1.0 - a.transmission);
        if !(k > 0.0 && wo.z > 0.0 && wi.z > 0.0) {
            return Rgb::ZERO;
        }
        let fo = fresnel_f32::dielectric(wo.z, self.eta).0;
        let fi = fresnel_f32::dielectric(wi.z, self.eta).0;
        self.base_color * (k * INV_PI * (1.0 - fo) * (1.0 - fi))
    }

    /// `(eval, pdf)` with the lobe weights `a` at `wo`.
    #[inline]
    fn eval_pdf_at(&self, a: &AtWo, wo: Vec3, wi: Vec3) -> (Rgb, f32) {
        let mut f = self.diffuse(a, wo, wi);
        let mut pdf = if a.p_diffuse > 0.0 && wi.z > 0.0 {
            a.p_diffuse * cosine_hemisphere_pdf(wi)
        } else {
            0.0
        };
        if self.smooth {
            return (f, pdf);
        }
        let Some((m, eta_p, reflect)) = half_vector(self.eta, wo, wi) else {
            return (f, pdf);
        };
        let (wo_m, wi_m) = (wo.dot(m), wi.dot(m));
        let fd = fresnel_f32::dielectric(wo_m, self.eta).0;
        let dist = &self.distribution;
        let d = dist.d(m);
        let g1_o = dist.g1(wo, m);
        let g = g1_o * dist.g1(wi, m);
        // pdf_visible(v, m) with v = wo flipped to the upper side.
        let pdf_m = g1_o * wo_m.abs() * d / wo.z.abs();
        let rho = self.reflect_prob(a, wo_m, fd);
        let p_micro = 1.0 - a.p_diffuse;
        if reflect {
            let common = d * g / (4.0 * (wo.z * wi.z).abs());
            let spec = if a.metallic > 0.0 {
                schlick(self.base_color, wo_m) * (a.metallic * common)
                    + Rgb::splat((1.0 - a.metallic) * fd * common)
            } else {
                Rgb::splat(d * g * fd / (4.0 * (wo.z * wi.z).abs()))
            };
            f += spec;
            pdf += p_micro * rho * pdf_m / (4.0 * wo_m.abs());
        } else {
            let k = (1.0 - a.metallic) * a.transmission;
            if k > 0.0 {
                let denom = (wi_m + wo_m / eta_p).powi(2);
                let v = d * g * (1.0 - fd) * (wi_m * wo_m).abs()
                    / ((wi.z * wo.z).abs() * denom)
                    / (eta_p * eta_p);
                f += self.base_color * (k * v);
                pdf += p_micro * (1.0 - rho) * pdf_m * wi_m.abs() / denom;
            }
        }
        (f, pdf)
    }

    /// `f(wo, wi)` without the cosine (the delta lobes excluded).
    #[inline]
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Rgb {
        self.eval_pdf(wo, wi).0
    }

    /// The mixture's solid-angle density of `wi` (the delta lobes excluded).
    #[inline]
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        self.eval_pdf(wo, wi).1
    }

    /// `(eval, pdf)` in one call.
    #[inline]
    pub fn eval_pdf(&self, wo: Vec3, wi: Vec3) -> (Rgb, f32) {
        match self.at_wo(wo) {
            Some(a) => self.eval_pdf_at(&a, wo, wi),
            None => (Rgb::ZERO, 0.0),
        }
    }

    /// Sample a lobe from the weights at `wo` (`u_lobe`), then a direction (`u`); see the
    /// module notes.
    #[inline]
    pub fn sample(&self, wo: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        let a = self.at_wo(wo)?;
        if u_lobe < a.p_diffuse {
            let wi = square_to_cosine_hemisphere(u);
            let (f, pdf) = self.eval_pdf_at(&a, wo, wi);
            if !(pdf > 0.0) {
                return None;
            }
            return Some(BsdfSample::reflected(wi, f, pdf));
        }
        let p_micro = 1.0 - a.p_diffuse;
        // `u_lobe` again uniform in [0, 1) for the reflect / refract choice.
        let u_lobe = ((u_lobe - a.p_diffuse) / p_micro).clamp(0.0, 1.0);
        if self.smooth {
            let (fd, cos_t, eta_it) = fresnel_f32::dielectric(wo.z, self.eta);
            let rho = self.reflect_prob(&a, wo.z, fd);
            if u_lobe < rho || rho >= 1.0 {
                let pdf = p_micro * rho;
                let spec = if a.metallic > 0.0 {
                    schlick(self.base_color, wo.z) * a.metallic
                        + Rgb::splat((1.0 - a.metallic) * fd)
                } else {
                    Rgb::splat(fd)
                };
                let mut s = mirror_sample(wo, pdf);
                s.weight = spec / pdf;
                return Some(s);
            }
            let pdf = p_micro * (1.0 - rho);
            let k = (1.0 - a.metallic) * a.transmission * (1.0 - fd);
            let mut s = refraction_sample(wo, cos_t, eta_it, pdf);
            s.weight = self.base_color * (s.weight.x * (k / pdf));
            return Some(s);
        }
        let v = wo * wo.z.signum();
        let m = self.distribution.sample_visible(v, u);
        let wo_m = wo.dot(m);
        let (fd, cos_t, eta_it) = fresnel_f32::dielectric(wo_m, self.eta);
        let rho = self.reflect_prob(&a, wo_m, fd);
        let (wi, eta) = if u_lobe < rho || rho >= 1.0 {
            let wi = reflect(wo, m);
            if wi.z * wo.z <= 0.0 {
                return None;
            }
            (wi, 1.0)
        } else {
            let wi = refract(wo, m, cos_t, 1.0 / eta_it).normalize();
            if wi.z * wo.z >= 0.0 || !wi.is_finite() {
                return None;
            }
            (wi, eta_it)
        };
        let (f, pdf) = self.eval_pdf_at(&a, wo, wi);
        if !(pdf > 0.0) || f == Rgb::ZERO {
            return None;
        }
        Some(BsdfSample {
            wi,
            weight: f * (wi.z.abs() / pdf),
            pdf,
            delta: false,
            eta,
        })
    }
}
