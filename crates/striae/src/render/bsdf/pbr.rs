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
//! * the diffuse lobe is `base / pi (1 - E(mu_o)) (1 - E(mu_i)) / (1 - E_avg)`, Kulla and
//!   Conty's reciprocal albedo scaling (2017, "Revisiting Physically Based Shading at
//!   Imageworks", the form [`super::multiscatter`] gives its conductor's multiple-scattering
//!   lobe), rather than Appendix B's `1 - F(wo.m)` at the half vector of `wo` and `wi`, which
//!   lets the albedo exceed 1 at grazing `wo`. `E(mu)` is the directional albedo of the
//!   specular reflection layer alone (GGX reflection with the exact Fresnel, single
//!   scattering; `F(mu)` at `alpha = 0`) and `E_avg = 2 int E(mu) mu dmu`, tabulated per `eta`
//!   over `mu` and `alpha` ([`LayerAlbedo`]; an anisotropic GGX's `alpha` is
//!   `sqrt(alpha_x alpha_y)`). The diffuse lobe's albedo is then `1 - E(mu_o)`: a white base
//!   under the non-transmitting layer reflects all the light but what the specular layer's
//!   single scattering loses, at every angle and roughness. Weighting by the smooth Fresnel at
//!   the macro normal, `(1 - F(wo.z)) (1 - F(wi.z))`, as this BSDF did, took far more at
//!   grazing `wo` than a rough layer reflects, and lost `F_avg` even at normal incidence: a
//!   `base 0.8, roughness 0.8` plane came out at 0.952, 0.902 and 0.748 of a Lambertian 0.8
//!   plane seen at 90, 30 and 15 degrees of elevation under a light overhead, where Blender's
//!   Cycles (Principled BSDF, whose albedo scaling is the one-sided `1 - E(mu_o)`) gives
//!   1.008, 0.990 and 0.972, and this scaling 1.016, 1.001 and 0.989. The tables are exact at
//!   `alpha = 0` and within about 2e-3 of the lobe they tabulate elsewhere, but for surfaces
//!   smoother than `alpha = 0.02` seen within 5 degrees of grazing, where `E` falls from
//!   `F(mu)` to the rough value between two roughness nodes (up to 0.01 off there, 0.04 in the
//!   last degree).
//! * seen from inside (`wo.z < 0`, only for a material that transmits) the surface is the
//!   tinted dielectric alone: the metal and diffuse parts are taken to face outward.
//!
//! Sampling. A lobe is chosen from the weights at `wo`: the diffuse lobe with probability
//! `p_d = w_d / (w_d + w_m)`, `w_d = (1 - metallic)(1 - transmission)(1 - E(mu_o))
//! mean(base)` (its albedo), `w_m = metallic mean(F_schlick(wo.z)) + (1 - metallic)(E(mu_o) +
//! transmission (1 - E(mu_o)))`; else a visible microfacet normal `m` is drawn and reflected with
//! probability `r / (r + t)`, `r = metallic mean(F_schlick(wo.m)) + (1 - metallic) F(wo.m)`,
//! `t = (1 - metallic) transmission (1 - F(wo.m))`, refracted otherwise (for `metallic = 0,
//! transmission = 1`: `F(wo.m)`, [`RoughDielectric`]'s choice). `pdf` is the whole mixture's
//! density, and a sample's weight `f |cos| / pdf`, so MIS stays correct. At `alpha = 0` the
//! reflection and refraction are deltas ([`BsdfSample::delta`], `pdf` the discrete
//! probability) beside the diffuse lobe, whose density alone `pdf` and `eval` report.

// `!(x > 0.0)` is meant: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use super::dielectric::{half_vector, mirror_sample, refract, refraction_sample};
use super::multiscatter::SquareGrid;
use super::BsdfSample;
use crate::math::{reflect, Rgb, Vec2, Vec3, INV_PI};
use crate::optics::fresnel_f32;
use crate::optics::microfacet::Ggx;
use crate::sampling::{cosine_hemisphere_pdf, square_to_cosine_hemisphere};
use std::sync::{Arc, Mutex, Weak};

/// The glTF metallic-roughness BSDF at one point (textures looked up), borrowing its
/// material's [`LayerAlbedo`] (or, in the lane vertex, a copy of the two rows it reads:
/// [`LayerRows`]).
#[derive(Debug, PartialEq)]
pub struct Pbr<'a, L = LayerAlbedo> {
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
    /// `E(mu, alpha)` of the specular reflection layer at `eta`.
    pub layer: &'a L,
    /// Where `alpha` (`sqrt(alpha_x alpha_y)`, 0 when smooth) falls among the table's
    /// roughness nodes ([`LayerAlbedo::node`]).
    pub layer_node: (usize, f32),
    /// `1 / (1 - E_avg(alpha))` (0 where `E_avg` rounds to 1).
    pub diffuse_norm: f32,
}

// (By hand: derived, `Clone` and `Copy` would ask the table to be `Copy` too.)
impl<L> Clone for Pbr<'_, L> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<L> Copy for Pbr<'_, L> {}

/// How the lobes share the light at one `wo`.
#[derive(Clone, Copy, Debug)]
struct AtWo {
    metallic: f32,
    transmission: f32,
    /// Probability of sampling the diffuse lobe.
    p_diffuse: f32,
}

impl AtWo {
    /// The weights for `wo` inside a transmitting BSDF: the tinted dielectric alone.
    const INSIDE: AtWo = AtWo {
        metallic: 0.0,
        transmission: 1.0,
        p_diffuse: 0.0,
    };
}

#[inline(always)]
fn mean(c: Rgb) -> f32 {
    (c.x + c.y + c.z) * (1.0 / 3.0)
}

/// Schlick's Fresnel with `f0` (glTF's `conductor_fresnel`), at the cosine `c`.
#[inline(always)]
fn schlick(f0: Rgb, c: f32) -> Rgb {
    let x = (1.0 - c.abs()).clamp(0.0, 1.0);
    let x2 = x * x;
    f0 + (Rgb::ONE - f0) * (x2 * x2 * x)
}

impl<'a> Pbr<'a> {
    /// A PBR BSDF of relative index `layer.eta()`; `alpha_t`, `alpha_b` are GGX alphas (0 and
    /// 0: smooth).
    pub fn new(
        base_color: Rgb,
        metallic: f32,
        transmission: f32,
        layer: &'a LayerAlbedo,
        alpha_t: f32,
        alpha_b: f32,
        transmits: bool,
    ) -> Self {
        let smooth = !(alpha_t > 0.0 || alpha_b > 0.0);
        let alpha = if smooth {
            0.0
        } else {
            (alpha_t.max(0.0) * alpha_b.max(0.0)).sqrt()
        };
        let layer_node = LayerAlbedo::node(alpha);
        let e_avg = layer.average_at(layer_node);
        let diffuse_norm = if 1.0 - e_avg > 1e-6 {
            1.0 / (1.0 - e_avg)
        } else {
            0.0
        };
        Pbr {
            base_color,
            metallic,
            transmission,
            eta: layer.eta,
            distribution: Ggx {
                alpha_x: alpha_t.max(Ggx::MIN_ALPHA),
                alpha_y: alpha_b.max(Ggx::MIN_ALPHA),
            },
            smooth,
            transmits,
            layer,
            layer_node,
            diffuse_norm,
        }
    }
}

impl<L: LayerLookup> Pbr<'_, L> {
    /// `E(mu)`, the directional albedo of the specular reflection layer alone at this `alpha`.
    #[inline(always)]
    pub fn layer_albedo(&self, mu: f32) -> f32 {
        self.layer.eval_at(self.layer_node, mu)
    }

    /// Whether every lobe is a delta (smooth, and no diffuse lobe).
    #[inline]
    pub fn is_delta(&self) -> bool {
        self.smooth
            && !((1.0 - self.metallic) * (1.0 - self.transmission) * mean(self.base_color) > 0.0)
    }

    /// The lobe weights at `wo`; `None` where the BSDF gives nothing (behind an opaque one).
    #[inline(always)]
    fn at_wo(&self, wo: Vec3) -> Option<AtWo> {
        if wo.z > 0.0 {
            let (a, gives) = self.at_wo_outside(wo);
            gives.then_some(a)
        } else if wo.z < 0.0 && self.transmits {
            Some(AtWo::INSIDE)
        } else {
            None
        }
    }

    /// [`Self::at_wo`] for `wo` outside (`wo.z > 0`), and whether the BSDF gives anything
    /// there (the weights' sum positive).
    #[inline(always)]
    fn at_wo_outside(&self, wo: Vec3) -> (AtWo, bool) {
        let (m, t) = (self.metallic, self.transmission);
        // The specular layer's albedo (`F(wo.z)` when smooth).
        let e = self.layer_albedo(wo.z);
        let w_d = (1.0 - m) * (1.0 - t) * (1.0 - e) * mean(self.base_color);
        let w_m = m * mean(schlick(self.base_color, wo.z)) + (1.0 - m) * (e + t * (1.0 - e));
        let sum = w_d + w_m;
        let a = AtWo {
            metallic: m,
            transmission: t,
            p_diffuse: w_d / sum,
        };
        (a, sum > 0.0)
    }

    /// Probability of reflecting (not refracting) through a microfacet seen at `wo_m` with
    /// dielectric Fresnel `fd`.
    #[inline(always)]
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

    /// The diffuse lobe, `(1 - m)(1 - t) base / pi (1 - E(mu_o)) (1 - E(mu_i)) / (1 - E_avg)`,
    /// both outside.
    #[inline(always)]
    fn diffuse(&self, a: &AtWo, wo: Vec3, wi: Vec3) -> Rgb {
        let k = (1.0 - a.metallic) * (1.0 - a.transmission);
        if !(k > 0.0 && wo.z > 0.0 && wi.z > 0.0) {
            return Rgb::ZERO;
        }
        let eo = self.layer_albedo(wo.z);
        let ei = self.layer_albedo(wi.z);
        self.base_color * (k * INV_PI * self.diffuse_norm * (1.0 - eo) * (1.0 - ei))
    }

    /// `(eval, pdf)` with the lobe weights `a` at `wo`.
    #[inline(always)]
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
    #[inline(always)]
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
            let reflects = u_lobe < rho || rho >= 1.0;
            return Some(self.smooth_lobe(&a, wo, p_micro, rho, reflects, (fd, cos_t, eta_it)));
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
        Some(BsdfSample::scattered(wi, f, pdf, eta))
    }

    /// The sample of a smooth BSDF's mirror (`reflects`) or refraction at `wo`, chosen among
    /// the specular lobes (probability `p_micro`) with the reflection's probability `rho`, from
    /// the smooth Fresnel terms `(fd, cos_t, eta_it)` of [`fresnel_f32::dielectric`].
    #[inline(always)]
    fn smooth_lobe(
        &self,
        a: &AtWo,
        wo: Vec3,
        p_micro: f32,
        rho: f32,
        reflects: bool,
        (fd, cos_t, eta_it): (f32, f32, f32),
    ) -> BsdfSample {
        if reflects {
            let pdf = p_micro * rho;
            let spec = if a.metallic > 0.0 {
                schlick(self.base_color, wo.z) * a.metallic + Rgb::splat((1.0 - a.metallic) * fd)
            } else {
                Rgb::splat(fd)
            };
            let mut s = mirror_sample(wo, pdf);
            s.weight = spec / pdf;
            s
        } else {
            let pdf = p_micro * (1.0 - rho);
            let k = (1.0 - a.metallic) * a.transmission * (1.0 - fd);
            let mut s = refraction_sample(wo, cos_t, eta_it, pdf);
            s.weight = self.base_color * (s.weight.x * (k / pdf));
            s
        }
    }

    /// [`Self::sample`] as the lane vertex runs it, smooth or rough, with the cosine lobe's
    /// direction `cosine_dir` and the visible normal's azimuth given
    /// ([`Ggx::sample_visible_at`]), written without early returns: the lobe weights outside
    /// and inside both made and one kept, the diffuse direction, the rough lobes' reflected
    /// and refracted ones and the smooth lobes' mirrored and refracted ones all made, the
    /// chosen one evaluated (a delta lobe weighted) and tested as `sample` tests it.
    #[inline(always)]
    pub fn sample_at(
        &self,
        wo: Vec3,
        u_lobe: f32,
        cosine_dir: Vec3,
        u_x: f32,
        azimuth: (f32, f32),
    ) -> Option<BsdfSample> {
        // `at_wo`'s weights: outside, or inside a transmitting BSDF; none elsewhere.
        let (outside, gives_outside) = self.at_wo_outside(wo);
        let inside = wo.z < 0.0 && self.transmits;
        let a = if inside { AtWo::INSIDE } else { outside };
        let gives = (wo.z > 0.0 && gives_outside) || inside;
        let diffuse = u_lobe < a.p_diffuse;
        // `sample`'s reflect / refract choice, through the visible normal `m` where rough.
        let p_micro = 1.0 - a.p_diffuse;
        let u_choice = ((u_lobe - a.p_diffuse) / p_micro).clamp(0.0, 1.0);
        let m = self
            .distribution
            .sample_visible_at(wo * wo.z.signum(), u_x, azimuth);
        let wo_m = if self.smooth { wo.z } else { wo.dot(m) };
        let (fd, cos_t, eta_it) = fresnel_f32::dielectric(wo_m, self.eta);
        let rho = self.reflect_prob(&a, wo_m, fd);
        let reflects = u_choice < rho || rho >= 1.0;
        let refracted = refract(wo, m, cos_t, 1.0 / eta_it).normalize();
        let delta = self.smooth && !diffuse;
        let specular = self.smooth_lobe(&a, wo, p_micro, rho, reflects, (fd, cos_t, eta_it));
        let wi = if diffuse {
            cosine_dir
        } else if delta {
            specular.wi
        } else if reflects {
            reflect(wo, m)
        } else {
            refracted
        };
        let eta = if diffuse || reflects { 1.0 } else { eta_it };
        let (f, pdf) = self.eval_pdf_at(&a, wo, wi);
        // `sample`'s tests of each lobe's direction and value (none of a smooth lobe).
        let side = wi.z * wo.z;
        let direction =
            diffuse | (reflects & !(side <= 0.0)) | (!reflects & !(side >= 0.0) & wi.is_finite());
        let valid = delta | ((pdf > 0.0) & direction & (diffuse | (f != Rgb::ZERO)));
        (gives & valid).then(|| {
            if delta {
                specular
            } else {
                BsdfSample::scattered(wi, f, pdf, eta)
            }
        })
    }
}

/// `E(mu)` at a roughness node `(k, t)` ([`LayerAlbedo::node`]): what [`Pbr`] reads of its
/// layer's table, the table itself or the lane vertex's copy of two rows ([`LayerRows`]).
pub trait LayerLookup {
    fn eval_at(&self, node: (usize, f32), mu: f32) -> f32;
}

/// `E(mu)` along a roughness node's row: linear in `sqrt(mu)` between the cosine nodes,
/// constant beyond the end ones.
#[inline(always)]
fn along_row(r: &[f32; MU_NODES], mu: f32) -> f32 {
    let x = (mu.max(0.0).sqrt() * MU_NODES as f32 - 0.5).clamp(0.0, (MU_NODES - 1) as f32);
    let i = (x as usize).min(MU_NODES - 2);
    let t = x - i as f32;
    r[i] + t * (r[i + 1] - r[i])
}

/// `E(mu)` at the roughness node `k` from its row `r`: the exact Fresnel at `k = 0` (smooth),
/// [`along_row`] above.
#[inline(always)]
fn at_node(eta: f32, r: &[f32; MU_NODES], k: usize, mu: f32) -> f32 {
    if k == 0 {
        fresnel_f32::dielectric(mu.clamp(0.0, 1.0), eta).0
    } else {
        along_row(r, mu)
    }
}

/// `E(mu)` at the roughness node `(k, t)` from the rows of nodes `k` (`lower`) and `k + 1`
/// (`upper`).
#[inline(always)]
fn between_rows(
    eta: f32,
    [lower, upper]: [&[f32; MU_NODES]; 2],
    (k, t): (usize, f32),
    mu: f32,
) -> f32 {
    let a = at_node(eta, lower, k, mu);
    if t > 0.0 {
        a + t * (along_row(upper, mu) - a)
    } else {
        a
    }
}

impl LayerLookup for LayerAlbedo {
    #[inline(always)]
    fn eval_at(&self, (k, t): (usize, f32), mu: f32) -> f32 {
        between_rows(self.eta, [&self.e[k], &self.e[k + 1]], (k, t), mu)
    }
}

/// The rows of a [`LayerAlbedo`] that a BSDF at one roughness reads (its node's and the
/// next one's), copied: the lane vertex's SIMD loop looks them up as gathers from each lane's
/// own copy, as it does the compensated BSDFs' tables.
#[derive(Clone, Copy, Debug)]
pub struct LayerRows {
    eta: f32,
    rows: [[f32; MU_NODES]; 2],
}

impl LayerRows {
    pub const ZERO: LayerRows = LayerRows {
        eta: 1.0,
        rows: [[0.0; MU_NODES]; 2],
    };

    /// The rows of `layer` at the roughness node `(k, _)`.
    #[inline(always)]
    pub fn of(layer: &LayerAlbedo, (k, _): (usize, f32)) -> Self {
        LayerRows {
            eta: layer.eta,
            rows: [layer.e[k], layer.e[k + 1]],
        }
    }
}

impl LayerLookup for LayerRows {
    #[inline(always)]
    fn eval_at(&self, node: (usize, f32), mu: f32) -> f32 {
        between_rows(self.eta, [&self.rows[0], &self.rows[1]], node, mu)
    }
}

/// Cosine nodes of a [`LayerAlbedo`]: `mu_i = s_i^2`, `s_i = (i + 1/2) / MU_NODES`, dense
/// toward grazing where the smooth Fresnel term falls fastest (it is linear in `mu` there,
/// so smooth in `s`).
const MU_NODES: usize = 32;
/// Roughness nodes of a [`LayerAlbedo`]: `alpha_k = (k / (ALPHA_NODES - 1))^2`.
const ALPHA_NODES: usize = 16;
/// Strata of the visible-normal sampler's square ([`SquareGrid`]) per `(mu, alpha)` node.
const STRATA: [usize; 2] = [16, 16];
/// Midpoints in `s` for `E_avg`.
const AVERAGE_POINTS: usize = 2048;

/// The directional albedo `E(mu, alpha)` of glTF's dielectric specular layer alone (GGX
/// reflection with the exact dielectric Fresnel at `eta`, single scattering) and its cosine
/// average `E_avg(alpha) = 2 int_0^1 E(mu, alpha) mu dmu`, which scale the diffuse lobe of
/// [`Pbr`] (the module notes).
///
/// `E` is tabulated at 32 cosines (`sqrt(mu)` evenly spaced, linear in `sqrt(mu)`
/// between, constant beyond the end nodes) and 16 roughnesses (`sqrt(alpha)`
/// evenly spaced, linear in `sqrt(alpha)` between); the node `alpha = 0` is the exact Fresnel
/// `F(mu)` (the delta reflection), not a table. Each other node is the mean of the sample
/// weight `F(wo.m) G1(wi, m)` (0 where `wi` falls below the horizon) of the same `f32` lobe
/// [`Pbr`] evaluates, over a 16 x 16 midpoint grid of the visible-normal sampler's square
/// (`multiscatter`'s, as its albedo tables use): deterministic, the same table on
/// every machine. `E_avg` at each roughness node is the average of that node's interpolant
/// (fine midpoint rule), so between nodes it is linear as `E` is: the diffuse lobe's
/// albedo `(1 - E(mu_o))` is exact for the table at every `alpha`. Cost: `15 * 32 * 256` =
/// 123k lobe samples, about 4 ms at opt-level 3; materials of equal `eta` share one table
/// ([`LayerAlbedo::shared`]).
#[derive(Clone, Debug, PartialEq)]
pub struct LayerAlbedo {
    eta: f32,
    /// `E(mu_i, alpha_k)` at `[k][i]`; row 0 is unused (the exact Fresnel).
    e: [[f32; MU_NODES]; ALPHA_NODES],
    /// `E_avg(alpha_k)`.
    average: [f32; ALPHA_NODES],
}

impl LayerAlbedo {
    /// The tables for the relative index `eta` (`n_inside / n_outside`).
    pub fn new(eta: f32) -> Self {
        let grid = SquareGrid::new(STRATA);
        let mut table = LayerAlbedo {
            eta,
            e: [[0.0; MU_NODES]; ALPHA_NODES],
            average: [0.0; ALPHA_NODES],
        };
        for k in 1..ALPHA_NODES {
            let alpha = (k as f32 / (ALPHA_NODES - 1) as f32).powi(2);
            let dist = Ggx {
                alpha_x: alpha.max(Ggx::MIN_ALPHA),
                alpha_y: alpha.max(Ggx::MIN_ALPHA),
            };
            for (i, e) in table.e[k].iter_mut().enumerate() {
                let s = (i as f32 + 0.5) / MU_NODES as f32;
                let mu = s * s;
                let wo = Vec3::new((1.0 - mu * mu).max(0.0).sqrt(), 0.0, mu);
                let mean = grid.mean(|u| {
                    let m = dist.sample_visible(wo, u);
                    let wo_m = wo.dot(m);
                    let wi = reflect(wo, m);
                    if !(wi.z > 0.0 && wo_m > 0.0) {
                        return 0.0;
                    }
                    (fresnel_f32::dielectric(wo_m, eta).0 * dist.g1(wi, m)) as f64
                });
                *e = mean.clamp(0.0, 1.0) as f32;
            }
        }
        for k in 0..ALPHA_NODES {
            // `2 int E(mu) mu dmu = 4 int E(s^2) s^3 ds`.
            let n = AVERAGE_POINTS;
            let sum: f64 = (0..n)
                .map(|j| {
                    let s = (j as f32 + 0.5) / n as f32;
                    (table.row(k, s * s) * s * s * s) as f64
                })
                .sum();
            table.average[k] = (4.0 * sum / n as f64) as f32;
        }
        table
    }

    /// The table for `eta`, shared with every other material of the same `eta` that holds one
    /// (built on first use; kept while some material holds it).
    pub fn shared(eta: f32) -> Arc<LayerAlbedo> {
        static TABLES: Mutex<Vec<Weak<LayerAlbedo>>> = Mutex::new(Vec::new());
        let mut tables = TABLES.lock().unwrap_or_else(|e| e.into_inner());
        tables.retain(|t| t.strong_count() > 0);
        if let Some(t) = tables
            .iter()
            .filter_map(Weak::upgrade)
            .find(|t| t.eta.to_bits() == eta.to_bits())
        {
            return t;
        }
        let t = Arc::new(LayerAlbedo::new(eta));
        tables.push(Arc::downgrade(&t));
        t
    }

    /// The relative index the table is for.
    #[inline]
    pub fn eta(&self) -> f32 {
        self.eta
    }

    /// The roughness node below `alpha` and the fraction of the way to the next one.
    #[inline]
    pub fn node(alpha: f32) -> (usize, f32) {
        let x = (alpha.max(0.0).sqrt() * (ALPHA_NODES - 1) as f32).min((ALPHA_NODES - 1) as f32);
        let k = (x as usize).min(ALPHA_NODES - 2);
        (k, x - k as f32)
    }

    /// `E(mu)` at the roughness node `k`.
    #[inline]
    fn row(&self, k: usize, mu: f32) -> f32 {
        at_node(self.eta, &self.e[k], k, mu)
    }

    /// `E_avg` at the roughness [`Self::node`] `(k, t)`.
    #[inline]
    fn average_at(&self, (k, t): (usize, f32)) -> f32 {
        self.average[k] + t * (self.average[k + 1] - self.average[k])
    }

    /// `E(mu, alpha)`, `mu` the cosine of `wo` (outside), `alpha` the GGX alpha (for an
    /// anisotropic one, `sqrt(alpha_x alpha_y)`; 0: smooth, `E = F(mu)`).
    #[inline]
    pub fn eval(&self, mu: f32, alpha: f32) -> f32 {
        self.eval_at(Self::node(alpha), mu)
    }

    /// `E_avg(alpha) = 2 int_0^1 E(mu, alpha) mu dmu`.
    #[inline]
    pub fn average(&self, alpha: f32) -> f32 {
        self.average_at(Self::node(alpha))
    }
}
