//! Materials at render time: prepared and immutable (presets resolved, textures loaded,
//! scratch tables attached; built from the scene file's description by
//! `scene::materials::MaterialDesc::prepare`), and the one function that makes a material's BSDF
//! at a hit, [`Material::shade`].

use crate::layers::CoverageCache;
use crate::math::{Frame, RayDifferential, Vec2, Vec3};
use crate::render::bsdf::{Bsdf, Conductor, ConductorIor, Dielectric, Diffuse};
use crate::render::bsdf::{ConductorCompensation, DielectricCompensation};
use crate::render::bsdf::{GrooveWall, RoughConductor, RoughDielectric};
use crate::render::geometry::SurfaceHit;
use crate::render::scratched::ScratchedMaterial;
use crate::render::shading::{hit_context, shading_frame, PixelHit};
use crate::render::texture::Texture;

/// A material ready to render.
#[derive(Clone, Debug)]
pub enum Material {
    /// Lambertian with a `reflectance` texture.
    Diffuse { reflectance: Texture },
    /// A dielectric interface of relative index `eta` (inside over outside); GGX `roughness`
    /// (alpha, 0 = smooth).
    Dielectric { eta: f32, roughness: f32 },
    /// A conductor of complex index `ior`; GGX `roughness` (alpha, 0 = smooth).
    Conductor { ior: ConductorIor, roughness: f32 },
    /// A rough dielectric with multiple-scattering compensation (`multiscatter = true`), its
    /// albedo tables built.
    CompensatedDielectric(Box<DielectricCompensation>),
    /// A rough conductor with multiple-scattering compensation (`multiscatter = true`).
    CompensatedConductor(Box<ConductorCompensation>),
    /// A smooth glass or metal base with scratches.
    Scratched(Box<ScratchedMaterial>),
    /// The opaque wall of an explicit scratch groove (METHOD.md 8.3).
    GrooveWall(GrooveWall),
}

/// How a hit is seen, for [`Material::shade`].
#[derive(Clone, Copy, Debug)]
pub struct HitView<'a> {
    /// Direction toward the viewer (world, unit).
    pub wo: Vec3,
    /// The arriving ray's differentials, where the material reads the footprint
    /// ([`Material::reads_footprint`]; else the footprint is zero).
    pub rd: Option<&'a RayDifferential>,
    /// A uniform random number, given exactly where the material reads the hit's context
    /// ([`Material::reads_hit_context`]).
    pub u_layer: Option<f32>,
    /// The pixel and chain of delta bounces of a camera path ([`PixelHit`]); read only with `rd`.
    pub pixel: Option<PixelHit>,
}

impl Material {
    /// Whether the material's BSDF transmits: [`Bsdf::has_transmission`] of the BSDF it gives at
    /// any hit, known before that BSDF is built (the shading frame's side depends on it).
    #[inline]
    pub fn has_transmission(&self) -> bool {
        match self {
            Material::Dielectric { .. } | Material::CompensatedDielectric(_) => true,
            Material::Diffuse { .. }
            | Material::Conductor { .. }
            | Material::CompensatedConductor(_)
            | Material::GrooveWall(_) => false,
            Material::Scratched(m) => m.has_transmission(),
        }
    }

    /// Whether the material's BSDF reads the pixel footprint (`ShadingContext::footprint_uv`):
    /// only the scratched material filters over it (not with `coverage = "point"`). When no
    /// material of a scene does, the integrator skips ray differentials altogether.
    pub fn reads_footprint(&self) -> bool {
        match self {
            Material::Scratched(m) => m.reads_footprint(),
            _ => false,
        }
    }

    /// Whether the BSDF at a hit seen from `wo` (world, toward the viewer) with geometric
    /// normal `ng` reads the hit's context (footprint, `u_layer`, pixel): the scratched
    /// material's, except glass seen from inside (its smooth base).
    #[inline]
    pub fn reads_hit_context(&self, wo: Vec3, ng: Vec3) -> bool {
        match self {
            Material::Scratched(m) => m.reads_hit_context(wo, ng),
            _ => false,
        }
    }

    /// Whether the BSDF at a hit that reads its context ([`Self::reads_hit_context`]) reads
    /// its footprint too: not scratched glass seen from inside.
    #[inline]
    pub fn reads_footprint_at(&self, wo: Vec3, ng: Vec3) -> bool {
        match self {
            Material::Scratched(m) => m.reads_footprint_at(wo, ng),
            _ => false,
        }
    }

    /// The shading frame at `hit` and the BSDF the material presents there, in that frame: the
    /// one place a material becomes a BSDF. The frame is flipped to `wo`'s side for opaque
    /// materials and guarded against `wo` falling behind the shading normal
    /// ([`shading_frame`]). The shading context (about 200 bytes) is built only for the
    /// scratched material seen from outside, the one material that reads it.
    ///
    /// `coverage` holds the render worker's scratch-coverage caches ([`CoverageCache`]).
    #[inline(always)]
    pub fn shade(
        &self,
        hit: &SurfaceHit,
        view: HitView<'_>,
        coverage: &mut CoverageCache,
    ) -> (Frame, Bsdf<'_>) {
        match self {
            Material::Scratched(m) => {
                let frame = shading_frame(hit, view.wo, m.has_transmission());
                let bsdf = match view.u_layer {
                    Some(u) => m.bsdf(
                        &hit_context(hit, view.rd, frame, view.wo, u, view.pixel),
                        coverage,
                    ),
                    // Glass seen from inside: its smooth base, whatever the context.
                    None => m.base_bsdf(),
                };
                (frame, bsdf)
            }
            // The other materials' BSDFs do not depend on the frame, so it is worked out after
            // them, from the BSDF: taking `self.has_transmission()` first makes the smooth
            // close-up 3.4 % slower (code layout).
            _ => {
                let bsdf = self.plain_bsdf(hit.uv);
                (shading_frame(hit, view.wo, bsdf.has_transmission()), bsdf)
            }
        }
    }

    /// The BSDF of a material that reads nothing of the hit but its texture coordinates (a
    /// scratched material gives its smooth base).
    #[inline(always)]
    fn plain_bsdf(&self, uv: Vec2) -> Bsdf<'_> {
        match self {
            Material::Diffuse { reflectance } => Bsdf::Diffuse(Diffuse::new(reflectance.eval(uv))),
            Material::Dielectric { eta, roughness } => {
                if *roughness > 0.0 {
                    Bsdf::RoughDielectric(RoughDielectric::new(*eta, *roughness))
                } else {
                    Bsdf::Dielectric(Dielectric::new(*eta))
                }
            }
            Material::Conductor { ior, roughness } => {
                if *roughness > 0.0 {
                    Bsdf::RoughConductor(RoughConductor::new(ior.eta, ior.k, *roughness))
                } else {
                    Bsdf::Conductor(Conductor { ior: *ior })
                }
            }
            Material::CompensatedDielectric(c) => Bsdf::CompensatedDielectric(c.bsdf()),
            Material::CompensatedConductor(c) => Bsdf::CompensatedConductor(c.bsdf()),
            Material::Scratched(m) => m.base_bsdf(),
            Material::GrooveWall(w) => Bsdf::Wall(*w),
        }
    }
}
