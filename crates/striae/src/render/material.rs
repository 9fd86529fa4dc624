//! Materials at render time: prepared and immutable (presets resolved, textures loaded,
//! scratch tables attached; built from the scene file's description by
//! `scene::materials::MaterialDesc::prepare`), and the one function that makes a material's BSDF
//! at a hit, [`Material::shade`].

use crate::layers::CoverageCache;
use crate::math::{Frame, RayDifferential, Rgb, Vec2, Vec3};
use crate::render::bsdf::{Bsdf, Conductor, ConductorIor, Dielectric, Diffuse};
use crate::render::bsdf::{ConductorCompensation, DielectricCompensation};
use crate::render::bsdf::{GrooveBelow, GrooveWall, LayerAlbedo, Pbr};
use crate::render::bsdf::{RoughConductor, RoughDielectric};
use crate::render::geometry::SurfaceHit;
use crate::render::scratched::ScratchedMaterial;
use crate::render::shading::{hit_context, shading_frame, PixelHit, ShadingContext};
use crate::render::texture::Texture;
use std::sync::Arc;

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
    /// glTF 2.0's metallic-roughness material ([`PbrMaterial`], BSDF [`Pbr`]).
    Pbr(Box<PbrMaterial>),
}

/// glTF 2.0's metallic-roughness material, prepared (textures loaded), built by
/// `scene::materials::PbrDesc::prepare`: the factors and textures of the description (same
/// names and meanings, checked there), its absorption coefficient, its anisotropy direction and
/// the albedo table of its specular layer.
#[derive(Clone, Debug)]
pub struct PbrMaterial {
    pub base_color: Texture,
    pub metallic: f32,
    /// Perceptual roughness (GGX `alpha = roughness^2`).
    pub roughness: f32,
    /// Green: roughness factor, blue: metallic factor.
    pub metallic_roughness: Option<Texture>,
    pub normal_map: Option<Texture>,
    pub normal_scale: f32,
    pub ior: f32,
    pub transmission: f32,
    /// KHR_materials_volume's absorption coefficient (per unit length), `None`: none.
    pub sigma_a: Option<Rgb>,
    /// KHR_materials_anisotropy's strength in `[0, 1]`.
    pub anisotropy: f32,
    /// `(cos, sin)` of the anisotropy direction's angle from `dP/du` toward the bitangent.
    pub anisotropy_direction: (f32, f32),
    /// `E(mu, alpha)` of the dielectric specular layer at `ior`, which scales the diffuse
    /// lobe ([`LayerAlbedo::shared`]: one per distinct `ior`).
    pub layer: Arc<LayerAlbedo>,
}

/// `-1` or `1`: the sign that turns `t` (a frame's second axis) toward decreasing `v`, the
/// image's up, which glTF's bitangent and the green of its normal maps point to.
#[inline(always)]
fn toward_image_up(t: Vec3, dpdv: Vec3) -> f32 {
    if t.dot(dpdv) > 0.0 {
        -1.0
    } else {
        1.0
    }
}

/// `frame` turned about its normal to the anisotropy direction `(cos, sin)` (its angle from
/// `s`, toward the bitangent that points toward decreasing `v`, as the normal map's), where
/// `dpdv` is the hit's `dP/dv` (KHR_materials_anisotropy).
#[inline(always)]
pub fn turned_to(frame: Frame, (cos, sin): (f32, f32), dpdv: Vec3) -> Frame {
    let w = toward_image_up(frame.t, dpdv);
    let s = (frame.s * cos + frame.t * (w * sin)).normalize_or(frame.s);
    Frame {
        s,
        t: frame.n.cross(s),
        n: frame.n,
    }
}

impl PbrMaterial {
    /// Whether light passes through anywhere on the surface (transmission and not all metal).
    #[inline]
    pub fn has_transmission(&self) -> bool {
        self.transmission > 0.0 && self.metallic < 1.0
    }

    /// The shading normal at `hit` with the normal map applied (glTF 2.0 section 3.9.3:
    /// `n = normalize(T x + B y + N z)` with `(x, y, z) = (2 c - 1) (scale, scale, 1)`), `T`
    /// along `dP/du` about the interpolated normal, `B = N x T` turned toward decreasing `v`
    /// (the image's up, glTF's green). `None` where the map leaves the normal as it is
    /// (`x = y = 0`), or gives a normal not on the geometric normal's side.
    #[inline]
    pub fn mapped_normal(&self, hit: &SurfaceHit) -> Option<Vec3> {
        let map = self.normal_map.as_ref()?;
        let c = map.eval(hit.uv) * 2.0 - Vec3::ONE;
        let (x, y, z) = (c.x * self.normal_scale, c.y * self.normal_scale, c.z);
        if x == 0.0 && y == 0.0 {
            return None;
        }
        let tangent = Frame::from_normal_tangent(hit.ns, hit.dpdu);
        let w = toward_image_up(tangent.t, hit.dpdv);
        let n = (tangent.s * x + tangent.t * (w * y) + tangent.n * z).normalize_or_zero();
        // `n` is finite (`normalize_or_zero`): zero fails the test too.
        if n.dot(hit.ng) * hit.ns.dot(hit.ng) <= 0.0 {
            return None;
        }
        Some(n)
    }

    /// The shading frame (normal map applied, then [`shading_frame`]'s side and guard; `s`
    /// turned to the anisotropy direction where there is anisotropy) and the BSDF at `hit`.
    #[inline]
    pub fn shade(&self, hit: &SurfaceHit, wo: Vec3) -> (Frame, Bsdf<'_>) {
        let transmits = self.has_transmission();
        let mut frame = match self.mapped_normal(hit) {
            Some(ns) => shading_frame(&SurfaceHit { ns, ..*hit }, wo, transmits),
            None => shading_frame(hit, wo, transmits),
        };
        let bsdf = self.bsdf_at(hit.uv, transmits);
        if self.anisotropy > 0.0 {
            frame = turned_to(frame, self.anisotropy_direction, hit.dpdv);
        }
        (frame, Bsdf::Pbr(bsdf))
    }

    /// Whether the BSDF at `uv` is clear smooth glass: all transmission, no metal, smooth (no
    /// anisotropy either, which makes it rough). It is then a delta BSDF whose [`Pbr::sample`]
    /// gives [`super::bsdf::Dielectric`]'s samples bit for bit, the refraction's weight times the
    /// base colour (but none for `wo` in the surface), and the lane vertex runs it as such.
    /// Reads the metallic-roughness texture, where there is one.
    #[inline(always)]
    pub fn is_clear_glass_at(&self, uv: Vec2) -> bool {
        if self.anisotropy != 0.0 || self.transmission != 1.0 || !self.has_transmission() {
            return false;
        }
        let (metallic, roughness) = self.metallic_roughness_at(uv);
        metallic == 0.0 && roughness * roughness == 0.0
    }

    /// The metallic factor and perceptual roughness at `uv`: the factors times the
    /// metallic-roughness texture's blue and green, where there is one.
    #[inline(always)]
    fn metallic_roughness_at(&self, uv: Vec2) -> (f32, f32) {
        let (mut metallic, mut roughness) = (self.metallic, self.roughness);
        if let Some(t) = &self.metallic_roughness {
            let c = t.eval(uv);
            roughness *= c.y;
            metallic *= c.z;
        }
        (metallic, roughness)
    }

    /// The BSDF at texture coordinates `uv` (`transmits`: [`Self::has_transmission`]), its
    /// GGX `alpha_x` the anisotropic `alpha_t` (along the anisotropy direction, the frame's `s`
    /// as [`Self::shade`] turns it).
    #[inline]
    pub fn bsdf_at(&self, uv: Vec2, transmits: bool) -> Pbr<'_> {
        let base = self.base_color.eval(uv);
        let (metallic, alpha_t, alpha_b) = self.metallic_alphas_at(uv);
        Pbr::new(
            base,
            metallic,
            self.transmission,
            &self.layer,
            alpha_t,
            alpha_b,
            transmits,
        )
    }

    /// The metallic factor and GGX's `alpha_t`, `alpha_b` at `uv`: `alpha = roughness^2`,
    /// KHR_materials_anisotropy's `alpha_t = mix(alpha, 1, strength^2)` and `alpha_b = alpha`.
    #[inline(always)]
    fn metallic_alphas_at(&self, uv: Vec2) -> (f32, f32, f32) {
        let (metallic, roughness) = self.metallic_roughness_at(uv);
        let alpha = roughness * roughness;
        let alpha_t = alpha + (1.0 - alpha) * self.anisotropy * self.anisotropy;
        (metallic, alpha_t, alpha)
    }
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
    /// [`crate::render::shading::ShadingContext::origin_depth`].
    pub origin_depth: f32,
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
            Material::Pbr(m) => m.has_transmission(),
        }
    }

    /// The absorption coefficient `sigma_a` (per unit length) inside the object the material
    /// bounds (KHR_materials_volume): a path segment that ends on the back side of such a
    /// surface (w.r.t. `SurfaceHit::ng`) is attenuated by `exp(-sigma_a t)` (the integrator).
    /// `None` for materials without absorption.
    #[inline]
    pub fn absorption(&self) -> Option<Rgb> {
        match self {
            Material::Pbr(m) => m.sigma_a,
            _ => None,
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

    /// The groove that light a groove at `hit` sent down into the glass meets next, below the
    /// surface ([`ScratchedMaterial::groove_below`]; `from` and `wi` in the hit's shading
    /// `frame`); `None` for every other material.
    #[inline]
    pub fn groove_below(
        &self,
        hit: &SurfaceHit,
        frame: Frame,
        from: Vec3,
        wi: Vec3,
        u: f32,
    ) -> Option<GrooveBelow<'_>> {
        match self {
            Material::Scratched(m) => {
                let ctx = hit_context(hit, None, frame, -frame.to_world(wi), u, None);
                m.groove_below(&ctx, from, wi, u)
            }
            _ => None,
        }
    }

    /// Whether the material picks its one lobe at a hit by the bounce's BSDF-lobe number
    /// (`layer_mix = "stochastic"`), which its BSDF's sampling then reads within the pick's
    /// share ([`crate::render::bsdf::LobeShare`]).
    #[inline]
    pub fn picks_lobe_by_lobe_number(&self) -> bool {
        match self {
            Material::Scratched(m) => m.mix == crate::render::scratched::LayerMix::Stochastic,
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
        let mut bsdf = Bsdf::Diffuse(Diffuse::new(Rgb::ZERO));
        let frame = self.shade_into(hit, view, coverage, &mut bsdf);
        (frame, bsdf)
    }

    /// [`Self::shade`] with the BSDF written into `bsdf`, in place: the path loop's form, which
    /// writes only the variant's own bytes where a returned `(Frame, Bsdf)` is copied whole (the
    /// size of the largest variant) on its way out.
    #[inline(always)]
    pub fn shade_into<'s>(
        &'s self,
        hit: &SurfaceHit,
        view: HitView<'_>,
        coverage: &mut CoverageCache,
        bsdf: &mut Bsdf<'s>,
    ) -> Frame {
        match self {
            Material::Scratched(m) => {
                let frame = shading_frame(hit, view.wo, m.has_transmission());
                *bsdf = match view.u_layer {
                    Some(u) => m.bsdf(
                        &ShadingContext {
                            origin_depth: view.origin_depth,
                            ..hit_context(hit, view.rd, frame, view.wo, u, view.pixel)
                        },
                        coverage,
                    ),
                    // Glass seen from inside: its smooth base, whatever the context.
                    None => m.base_bsdf(),
                };
                frame
            }
            Material::Pbr(m) => {
                let frame;
                (frame, *bsdf) = m.shade(hit, view.wo);
                frame
            }
            // The other materials' BSDFs do not depend on the frame, so it is worked out after
            // them, from the BSDF: taking `self.has_transmission()` first makes the smooth
            // close-up 3.4 % slower (code layout).
            _ => {
                *bsdf = self.plain_bsdf(hit.uv);
                shading_frame(hit, view.wo, bsdf.has_transmission())
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
            Material::Pbr(m) => Bsdf::Pbr(m.bsdf_at(uv, m.has_transmission())),
        }
    }
}
