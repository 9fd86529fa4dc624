//! BSDFs in a local shading frame (`z` = shading normal; `wo`, `wi` point away), the
//! surface-scattering part of the path tracer (`docs/METHOD.md` section 7 uses them
//! as the base layer under the scratches).
//!
//! Five models, each in its own file, gathered in the closed enum [`Bsdf`] so the integrator
//! dispatches without virtual calls:
//!
//! * [`Diffuse`], Lambertian.
//! * [`Dielectric`], a smooth interface with the exact Fresnel equations (Mitsuba 3's
//!   `dielectric`, pbrt-v4's `DielectricBxDF` with zero roughness).
//! * [`Conductor`], a smooth mirror with a complex index of refraction per RGB channel.
//! * [`RoughConductor`] and [`RoughDielectric`], GGX microfacet models after Walter et al. 2007,
//!   sampled by visible normals (Heitz 2018), with the separable Smith shadowing
//!   `G = G1(wo) G1(wi)` that Mitsuba 3 uses (so that renders agree with it).
//! * [`CompensatedConductor`] and [`CompensatedDielectric`], the two rough models with the
//!   energy their single scattering loses restored (`multiscatter = true`; Kulla and Conty
//!   2017, Turquin 2019; module [`multiscatter`]).
//! * [`Pbr`], glTF 2.0's metallic-roughness BSDF (its Appendix B) with transmission, IOR and
//!   anisotropy: a metal, dielectric-over-diffuse and rough or smooth glass mixture that
//!   reuses the dielectric's lobes (module [`pbr`]).
//!
//! ## Conventions
//!
//! * `eval(wo, wi)` is `f` without the cosine; `pdf(wo, wi)` is per unit solid angle and 0 for
//!   delta lobes; `sample` returns [`BsdfSample`] with `weight = f |cos theta_i| / pdf`.
//! * Opaque BSDFs (diffuse, conductors) are one-sided in the local frame: they return 0 unless
//!   both `wo.z > 0` and `wi.z > 0`; the integrator flips the frame to `wo`'s side first
//!   (`docs/ARCHITECTURE.md`).
//! * Transmissive BSDFs see `wo.z < 0` when `wo` is inside the medium the normal points away
//!   from. The relative index `eta = n_inside / n_outside`.
//! * **Radiance transport**: refraction into a medium of relative index `eta_t` (seen from
//!   `wo`'s side) scales radiance by `1 / eta_t^2` (pbrt-v4's `TransportMode::Radiance`,
//!   Mitsuba 3's `dielectric` in radiance mode). [`BsdfSample::eta`] reports that relative
//!   index so Russian roulette can undo the scaling.
//!
//! The scratched variants ([`ScratchedBsdf`], [`ScratchedGlassBsdf`], [`ScratchedMetalBsdf`])
//! borrow the scene's scratch table, so [`Bsdf`] carries the lifetime of the material it came from.

// `!(x > 0.0)` is used on purpose: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

mod conductor;
mod dielectric;
mod diffuse;
pub mod multiscatter;
pub mod pbr;
pub mod scratched;
pub mod scratched_glass;
pub mod scratched_metal;
mod wall;

pub use conductor::{Conductor, ConductorIor, RoughConductor, CONDUCTOR_PRESETS};
pub use dielectric::{Dielectric, RoughDielectric};
pub use diffuse::Diffuse;
pub use multiscatter::{
    AlbedoTable, CompensatedConductor, CompensatedDielectric, ConductorCompensation,
    DielectricCompensation,
};
pub use pbr::{LayerAlbedo, LayerLookup, LayerRows, Pbr};
pub use scratched::{
    GroovePlace, LobeShare, ScratchLobe, ScratchLobeTable, ScratchedBase, ScratchedBsdf,
};
pub use scratched_glass::{
    GlassWalls, GrooveBelow, ScratchedGlassBsdf, TracedGroove, WallLobeTable,
};
pub use scratched_metal::ScratchedMetalBsdf;
pub use wall::GrooveWall;

use crate::math::{Rgb, Vec2, Vec3};

/// One sampled incident direction.
#[derive(Clone, Copy, Debug)]
pub struct BsdfSample {
    /// Sampled direction, local frame, unit length, pointing away from the surface.
    pub wi: Vec3,
    /// `f(wo, wi) |cos theta_i| / pdf` (for a delta lobe: the lobe's weight).
    pub weight: Rgb,
    /// Solid-angle density of `wi` (for a delta lobe: the discrete probability of choosing it).
    pub pdf: f32,
    /// Whether `wi` came from a delta (specular) lobe, which light sampling cannot reach.
    pub delta: bool,
    /// Relative index of refraction `n_i / n_o` crossed by the sample (1 for reflection),
    /// used to keep Russian roulette independent of the radiance scaling at refraction.
    pub eta: f32,
    /// Where the path goes on from, relative to the hit (local frame, world units), where it
    /// does not go on from the hit itself: light that left a groove's wall inside the object
    /// and heads up for the surface beside the opening, where the next hit looks the
    /// scratches up again (traced glass walls seen from inside, METHOD.md 8.1); `wi` then
    /// points up inside the object. Light such a groove sent down into the object (`wi`
    /// pointing down) gives the wall it left, where the path loop looks for the grooves it
    /// runs under ([`crate::render::material::Material::groove_below`]), going on from the hit
    /// past them. On the surface (`z = 0`): the point of the covering scratch a footprint's
    /// lobe goes on from ([`ScratchLobe::spawn`]). `None` for every other sample.
    pub from: Option<Vec3>,
}

impl BsdfSample {
    /// Where light a groove sent down into the object left its wall ([`Self::from`] below the
    /// surface with `wi` pointing down), if this sample is such light.
    #[inline]
    pub fn sent_down(&self) -> Option<Vec3> {
        self.from.filter(|f| f.z < 0.0 && self.wi.z < 0.0)
    }

    /// A non-delta sample that stays on `wo`'s side: `weight = f |cos theta_i| / pdf`.
    #[inline(always)]
    pub fn reflected(wi: Vec3, f: Rgb, pdf: f32) -> Self {
        Self::scattered(wi, f, pdf, 1.0)
    }

    /// A non-delta sample of relative index `eta` (1 where it stays on `wo`'s side): `weight =
    /// f |cos theta_i| / pdf`.
    #[inline(always)]
    pub fn scattered(wi: Vec3, f: Rgb, pdf: f32, eta: f32) -> Self {
        BsdfSample {
            wi,
            weight: f * (wi.z.abs() / pdf),
            pdf,
            delta: false,
            eta,
            from: None,
        }
    }
}

/// A BSDF evaluated at one surface point (textures already looked up).
#[derive(Clone, Copy, Debug)]
pub enum Bsdf<'a> {
    Diffuse(Diffuse),
    Dielectric(Dielectric),
    Conductor(Conductor),
    RoughDielectric(RoughDielectric),
    RoughConductor(RoughConductor),
    /// [`RoughDielectric`] with multiple-scattering compensation.
    CompensatedDielectric(CompensatedDielectric<'a>),
    /// [`RoughConductor`] with multiple-scattering compensation.
    CompensatedConductor(CompensatedConductor<'a>),
    /// A smooth dielectric or conductor with scratches (METHOD.md section 6).
    Scratched(ScratchedBsdf<'a>),
    /// Glass with dielectric-wall scratches, reflecting and transmitting (METHOD.md 8.2).
    ScratchedGlass(ScratchedGlassBsdf<'a>),
    /// Metal with rough-walled scratches (METHOD.md 8.1).
    ScratchedMetal(ScratchedMetalBsdf<'a>),
    /// The wall of an explicit scratch groove (METHOD.md 8.3).
    Wall(GrooveWall),
    /// glTF 2.0's metallic-roughness BSDF.
    Pbr(Pbr<'a>),
}

impl Bsdf<'_> {
    /// `f(wo, wi)` without the cosine (0 for delta lobes).
    #[inline(always)]
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Rgb {
        match self {
            Bsdf::Diffuse(b) => b.eval(wo, wi),
            Bsdf::Dielectric(_) | Bsdf::Conductor(_) => Rgb::ZERO,
            Bsdf::RoughDielectric(b) => b.eval(wo, wi),
            Bsdf::RoughConductor(b) => b.eval(wo, wi),
            Bsdf::CompensatedDielectric(b) => b.eval(wo, wi),
            Bsdf::CompensatedConductor(b) => b.eval(wo, wi),
            Bsdf::Scratched(b) => b.eval(wo, wi),
            Bsdf::ScratchedGlass(b) => b.eval(wo, wi),
            Bsdf::ScratchedMetal(b) => b.eval_pdf(wo, wi).0,
            Bsdf::Wall(b) => b.eval(wo, wi),
            Bsdf::Pbr(b) => b.eval(wo, wi),
        }
    }

    /// Solid-angle density with which [`Bsdf::sample`] returns `wi` (0 for delta lobes).
    #[inline(always)]
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        match self {
            Bsdf::Diffuse(b) => b.pdf(wo, wi),
            Bsdf::Dielectric(_) | Bsdf::Conductor(_) => 0.0,
            Bsdf::RoughDielectric(b) => b.pdf(wo, wi),
            Bsdf::RoughConductor(b) => b.pdf(wo, wi),
            Bsdf::CompensatedDielectric(b) => b.pdf(wo, wi),
            Bsdf::CompensatedConductor(b) => b.pdf(wo, wi),
            Bsdf::Scratched(b) => b.pdf(wo, wi),
            Bsdf::ScratchedGlass(b) => b.pdf(wo, wi),
            Bsdf::ScratchedMetal(b) => b.eval_pdf(wo, wi).1,
            Bsdf::Wall(b) => b.pdf(wo, wi),
            Bsdf::Pbr(b) => b.pdf(wo, wi),
        }
    }

    /// `(eval(wo, wi), pdf(wo, wi))` in one call, sharing the work the two have in common
    /// (the microfacet models compute the half vector, `D` and Fresnel once). Use it for light
    /// sampling with MIS.
    #[inline]
    pub fn eval_pdf(&self, wo: Vec3, wi: Vec3) -> (Rgb, f32) {
        match self {
            Bsdf::Diffuse(b) => (b.eval(wo, wi), b.pdf(wo, wi)),
            Bsdf::Dielectric(_) | Bsdf::Conductor(_) => (Rgb::ZERO, 0.0),
            Bsdf::RoughDielectric(b) => b.eval_pdf(wo, wi),
            Bsdf::RoughConductor(b) => b.eval_pdf(wo, wi),
            Bsdf::CompensatedDielectric(b) => b.eval_pdf(wo, wi),
            Bsdf::CompensatedConductor(b) => b.eval_pdf(wo, wi),
            Bsdf::Scratched(b) => b.eval_pdf(wo, wi),
            Bsdf::ScratchedGlass(b) => b.eval_pdf(wo, wi),
            Bsdf::ScratchedMetal(b) => b.eval_pdf(wo, wi),
            Bsdf::Wall(b) => (b.eval(wo, wi), b.pdf(wo, wi)),
            Bsdf::Pbr(b) => b.eval_pdf(wo, wi),
        }
    }

    /// `eval(wo, wi)` for light sampling, with `pdf(wo, wi)` when the model gets it for
    /// little more (the scratched BSDF: the same table lookups) and the light is not a delta
    /// one (whose MIS weight needs no BSDF density); `None` leaves it to a later [`Bsdf::pdf`]
    /// call, made only if the shadow ray is unoccluded. The same values as `eval` and `pdf`.
    #[inline(always)]
    pub fn eval_for_light(&self, wo: Vec3, wi: Vec3, delta_light: bool) -> (Rgb, Option<f32>) {
        match self {
            Bsdf::Scratched(b) if !delta_light => {
                let (f, pdf) = b.eval_pdf(wo, wi);
                (f, Some(pdf))
            }
            Bsdf::ScratchedGlass(b) if !delta_light => {
                let (f, pdf) = b.eval_pdf(wo, wi);
                (f, Some(pdf))
            }
            Bsdf::ScratchedMetal(b) if !delta_light => {
                let (f, pdf) = b.eval_pdf(wo, wi);
                (f, Some(pdf))
            }
            _ => (self.eval(wo, wi), None),
        }
    }

    /// Sample `wi` given `wo`: `u_lobe` chooses between lobes (reflection / transmission),
    /// `u` drives the direction. `None` when no direction is produced (wrong side, a
    /// microfacet sample below the surface): the path ends.
    #[inline(always)]
    pub fn sample(&self, wo: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        match self {
            Bsdf::Diffuse(b) => b.sample(wo, u),
            Bsdf::Dielectric(b) => b.sample(wo, u_lobe),
            Bsdf::Conductor(b) => b.sample(wo),
            Bsdf::RoughDielectric(b) => b.sample(wo, u_lobe, u),
            Bsdf::RoughConductor(b) => b.sample(wo, u),
            Bsdf::CompensatedDielectric(b) => b.sample(wo, u_lobe, u),
            Bsdf::CompensatedConductor(b) => b.sample(wo, u_lobe, u),
            Bsdf::Scratched(b) => b.sample(wo, u_lobe, u),
            Bsdf::ScratchedGlass(b) => b.sample(wo, u_lobe, u),
            Bsdf::ScratchedMetal(b) => b.sample(wo, u_lobe, u),
            Bsdf::Wall(b) => b.sample(wo, u),
            Bsdf::Pbr(b) => b.sample(wo, u_lobe, u),
        }
    }

    /// Whether light can pass through (the integrator then keeps `wo.z < 0` as "inside"
    /// instead of flipping the frame).
    #[inline]
    pub fn has_transmission(&self) -> bool {
        match self {
            Bsdf::Dielectric(_)
            | Bsdf::RoughDielectric(_)
            | Bsdf::CompensatedDielectric(_)
            | Bsdf::ScratchedGlass(_) => true,
            Bsdf::Scratched(b) => b.has_transmission(),
            Bsdf::Pbr(b) => b.transmits,
            _ => false,
        }
    }

    /// Whether light sampling is skipped: every lobe is a delta, or nearly (smooth dielectric
    /// walls' groove lobes, boxes of 0.35 degrees in `theta` that a light sample hardly ever
    /// lands in). The integrator then counts emission found by BSDF sampling fully.
    #[inline]
    pub fn is_delta(&self) -> bool {
        match self {
            Bsdf::Dielectric(_) | Bsdf::Conductor(_) => true,
            Bsdf::Scratched(b) => b.is_delta(),
            Bsdf::ScratchedGlass(b) => b.walls.smooth(),
            Bsdf::Wall(b) => b.specular,
            Bsdf::Pbr(b) => b.is_delta(),
            _ => false,
        }
    }
}

#[cfg(test)]
mod tests;
