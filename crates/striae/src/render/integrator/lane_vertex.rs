//! The vertex of a plain material in lanes: [`Path::land`]'s operations for up to [`LANES`]
//! paths at once where their rays met a diffuse surface, a smooth dielectric (scratched glass
//! seen from inside included: its smooth base; and glTF's clear smooth glass, its refraction
//! tinted), a smooth conductor, a rough (GGX) dielectric or conductor, with or without
//! multiple-scattering compensation, or glTF's metallic-roughness BSDF ([`Kind`]), on a shape
//! that emits or not, in three stages:
//!
//! 1. **Gather**, lane by lane: the emission found at the hit (into the path's radiance, as
//!    `land` counts it), the hit, the path's throughput, the bounce's random numbers
//!    (the dimensions `land` reads, drawn in its order), the texture, the light sample, the
//!    cosine-weighted direction and the GGX visible normal's azimuth (each a scalar call:
//!    `sincosf`, `cosf`, `sinf` and the `Texture` and `Light` enums do not vectorise) into
//!    structure-of-arrays [`Lanes`], a compensated BSDF's albedo tables (glTF's BSDF: the two
//!    rows of its layer table it reads) into [`LaneTables`].
//! 2. **The vertex** ([`Lanes::run`]), one loop over the lanes whose body is the scalar code's own
//!    functions (shading frame, next-event estimation's BSDF value and MIS weight, Fresnel, the
//!    throughput's update, the spawned rays, Russian roulette) with every decision a select, so
//!    that the render loop's SIMD copies run it 8 or 16 lanes at a time; then, for the lanes that
//!    hold a GGX BSDF, its own `eval`, `pdf` and `sample` ([`RoughDielectric`], [`RoughConductor`],
//!    `CompensatedDielectric`, `CompensatedConductor`, [`Pbr`]), written without early returns,
//!    whose results replace the first loop's there: a loop over all lanes per BSDF (the tables'
//!    lookups gathers), for the BSDFs the render loop's copy vectorises ([`simd_ggx`]); [`takes`]
//!    leaves the others to `land`. The functions these loops call are inlined always: left to
//!    LLVM's choice (the Fresnel laws, once the GGX code called them too), they stayed calls and
//!    the loops scalar.
//! 3. **Scatter**, lane by lane: the path's new ray and state, its deferred shadow test.
//!
//! Each lane runs the operations of `land` on the same numbers, so the image is `land`'s bit
//! for bit (`tests/lanes.rs` on every shipped scene; `lane_vertex_equals_land` lane by lane).

// `!(x > 0.0)` is meant: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use super::lanes::LANES;
use super::path::{
    chosen_light, light_select_pdf, max_depth, shadow_t_max, survival_probability, DeferredBounce,
    Path, ShadowTest,
};
use super::Worker;
use crate::math::{reflect_z, Frame, Ray, Rgb, Vec2, Vec3};
use crate::optics::fresnel_f32;
use crate::optics::microfacet::{visible_azimuth, Ggx};
use crate::render::bsdf::{
    AlbedoTable, Bsdf, BsdfSample, CompensatedConductor, CompensatedDielectric, ConductorIor,
    LayerRows, Pbr, RoughConductor, RoughDielectric,
};
use crate::render::geometry::{offset_origin_by, SurfaceHit};
use crate::render::material::{turned_to, Material};
use crate::render::scene::{Scene, NO_MATERIAL};
use crate::render::shading::shading_frame_of;
use crate::sampling::{cosine_hemisphere_pdf, power_heuristic, square_to_cosine_hemisphere};

/// The BSDFs the lane vertex runs.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[repr(u8)]
pub(super) enum Kind {
    /// `Diffuse`, with next-event estimation.
    Diffuse,
    /// A smooth `Dielectric`.
    Glass,
    /// A smooth `Conductor`.
    Mirror,
    /// A rough (GGX) `Dielectric`, with next-event estimation.
    RoughGlass,
    /// A rough (GGX) `Conductor`, with next-event estimation.
    RoughMetal,
    /// A `CompensatedDielectric` (`multiscatter = true`), with next-event estimation.
    CompensatedGlass,
    /// A `CompensatedConductor` (`multiscatter = true`), with next-event estimation.
    CompensatedMetal,
    /// glTF's metallic-roughness `Pbr` (but clear smooth glass, a `Glass`): rough or smooth,
    /// opaque or transmitting, its shading normal the normal map's (taken in gather), its
    /// frame turned to the anisotropy direction where there is anisotropy; with next-event
    /// estimation where it is not a delta BSDF (`Pbr::is_delta`: smooth, no diffuse lobe).
    Pbr,
}

impl Kind {
    /// A delta BSDF: no next-event estimation, and the bounce is specular (a `Pbr` may be
    /// one too: [`Lanes::gather`] tells).
    #[inline(always)]
    fn is_delta(self) -> bool {
        matches!(self, Kind::Glass | Kind::Mirror)
    }

    /// A GGX kind's [`ggx_slot`] (the PBR BSDF's [`PBR_SLOT`]): its index in [`Lanes`]'
    /// masks, its bit `1 << slot` in a [`simd_ggx`] set; `None` for the others.
    #[inline(always)]
    fn slot(self) -> Option<usize> {
        match self {
            Kind::RoughGlass => Some(ggx_slot(true, false)),
            Kind::RoughMetal => Some(ggx_slot(false, false)),
            Kind::CompensatedGlass => Some(ggx_slot(true, true)),
            Kind::CompensatedMetal => Some(ggx_slot(false, true)),
            Kind::Pbr => Some(PBR_SLOT),
            Kind::Diffuse | Kind::Glass | Kind::Mirror => None,
        }
    }

    /// Run by a GGX loop ([`Lanes::run`]).
    #[inline(always)]
    fn is_rough(self) -> bool {
        self.slot().is_some()
    }

    /// Taken by the lane vertex of a render loop copy that runs the GGX kinds `simd_ggx` in
    /// SIMD lanes ([`simd_ggx`]).
    #[inline(always)]
    fn taken_with(self, simd_ggx: u32) -> bool {
        self.slot().is_none_or(|slot| simd_ggx & (1 << slot) != 0)
    }

    /// The GGX kind: a dielectric (`glass`) or a conductor, compensated or not.
    #[inline(always)]
    const fn ggx(glass: bool, compensated: bool) -> Kind {
        match (glass, compensated) {
            (true, false) => Kind::RoughGlass,
            (false, false) => Kind::RoughMetal,
            (true, true) => Kind::CompensatedGlass,
            (false, true) => Kind::CompensatedMetal,
        }
    }
}

/// The index of the GGX kind `Kind::ggx(glass, compensated)` in [`Lanes`]' masks and the bit
/// `1 << ggx_slot(..)` of it in a [`simd_ggx`] set.
#[inline(always)]
const fn ggx_slot(glass: bool, compensated: bool) -> usize {
    glass as usize + 2 * compensated as usize
}

/// [`Kind::Pbr`]'s index in [`Lanes`]' masks and its bit's in a [`simd_ggx`] set, after the
/// four [`ggx_slot`]s.
const PBR_SLOT: usize = 4;

/// The sets of GGX kinds a copy of the render loop runs in SIMD lanes (its `SIMD_GGX`), as
/// bits `1 << ggx_slot(..)` (a `u32`: const generic parameters are integers). Each is a loop
/// over every lane, worth it where the copy vectorises it; the lane vertex leaves the kinds
/// not in the set to `land` ([`takes`]). The sets per copy are measured (BENCHMARKS.md "The
/// lane loop"; instructions at 128 x 96, 9 less 1 spp).
pub(super) mod simd_ggx {
    use super::{ggx_slot, PBR_SLOT};
    pub const ROUGH_GLASS: u32 = 1 << ggx_slot(true, false);
    pub const ROUGH_METAL: u32 = 1 << ggx_slot(false, false);
    pub const COMPENSATED_GLASS: u32 = 1 << ggx_slot(true, true);
    pub const COMPENSATED_METAL: u32 = 1 << ggx_slot(false, true);
    pub const PBR: u32 = 1 << PBR_SLOT;
    /// The portable copy's: its GGX loops stay scalar, and every lane's GGX costs more than
    /// `land` in the lanes that hold one.
    pub const NONE: u32 = 0;
    /// The AVX2 copy's: it vectorises these three loops 8 wide; the compensated conductor's
    /// and glTF's BSDF's it leaves scalar, and those loops, in every lane, cost more than
    /// `land` in the lanes that hold one (compensated gold 433 against 335 M instructions;
    /// `pbr.toml` without absorption, one thread: 2.04 against 1.28 s left to `land`).
    pub const AVX2: u32 = ROUGH_GLASS | ROUGH_METAL | COMPENSATED_GLASS;
    /// The AVX-512 copy's: all five vectorised 16 wide (compensated gold, one thread: 1.23 s
    /// against 1.33 s with its vertices left to `land`; `pbr.toml` without absorption: 1.31
    /// against 1.35 s).
    pub const ALL: u32 = ROUGH_GLASS | ROUGH_METAL | COMPENSATED_GLASS | COMPENSATED_METAL | PBR;
}

/// The lane vertex's BSDF for the vertex of a path at `depth` whose ray met `hit`, arriving
/// along `d`, if it takes it: a diffuse, dielectric or conductor material, smooth or rough (or
/// scratched glass seen from inside, or glTF's BSDF), below the depth limit (what `land` does
/// there after Beer-Lambert absorption and the emission found, which `Lanes::gather` applies
/// first). The GGX kinds only where the render loop's copy runs them in SIMD lanes
/// (`SIMD_GGX`, a [`simd_ggx`] set).
#[inline(always)]
pub(super) fn takes<const SIMD_GGX: u32>(
    scene: &Scene,
    hit: &SurfaceHit,
    depth: u32,
    d: Vec3,
) -> Option<Kind> {
    let shape = &scene.geometry.shapes()[hit.shape as usize];
    if shape.material == NO_MATERIAL || depth + 2 > max_depth(scene) {
        return None;
    }
    let kind = match &scene.materials[shape.material as usize] {
        Material::Diffuse { .. } => Kind::Diffuse,
        // (`Material::plain_bsdf`'s choice between the smooth and the GGX BSDF.)
        Material::Dielectric { roughness, .. } if *roughness > 0.0 => Kind::RoughGlass,
        Material::Dielectric { .. } => Kind::Glass,
        Material::Conductor { roughness, .. } if *roughness > 0.0 => Kind::RoughMetal,
        Material::Conductor { .. } => Kind::Mirror,
        Material::CompensatedDielectric(_) => Kind::CompensatedGlass,
        Material::CompensatedConductor(_) => Kind::CompensatedMetal,
        Material::Pbr(m) if m.is_clear_glass_at(hit.uv) => Kind::Glass,
        Material::Pbr(_) => Kind::Pbr,
        Material::Scratched(m) if m.has_transmission() && !m.reads_hit_context(-d, hit.ng) => {
            Kind::Glass
        }
        _ => return None,
    };
    kind.taken_with(SIMD_GGX).then_some(kind)
}

/// Three-component vectors over the lanes, a component an array: loads and stores of one
/// lane's vector that the lane loop's SIMD copies run for 8 or 16 lanes at once without
/// shuffles.
#[derive(Clone, Copy)]
struct Soa3([[f32; LANES]; 3]);

impl Soa3 {
    fn splat(v: Vec3) -> Self {
        Soa3([[v.x; LANES], [v.y; LANES], [v.z; LANES]])
    }

    #[inline(always)]
    fn get(&self, i: usize) -> Vec3 {
        Vec3::new(self.0[0][i], self.0[1][i], self.0[2][i])
    }

    #[inline(always)]
    fn set(&mut self, i: usize, v: Vec3) {
        self.0[0][i] = v.x;
        self.0[1][i] = v.y;
        self.0[2][i] = v.z;
    }
}

/// A lane's inputs and results, each field an array over the lanes.
#[derive(Clone, Copy)]
pub(super) struct Lanes {
    // The hit and the path that reached it.
    kind: [Kind; LANES],
    wo: Soa3,
    p: Soa3,
    ng: Soa3,
    ns: Soa3,
    dpdu: Soa3,
    /// The spawned rays' offset ([`crate::render::geometry::Geometry::spawn_offset`]).
    rel: [f32; LANES],
    beta: Soa3,
    eta_scale: [f32; LANES],
    /// Russian roulette after this bounce, with this number.
    roulette: [bool; LANES],
    u_roulette: [f32; LANES],
    /// A delta BSDF (1; [`Kind::is_delta`], or a `Pbr`'s): no light sample, a specular bounce.
    delta_bsdf: [u32; LANES],
    // Diffuse: the reflectance, the cosine-weighted direction, the light sample where there is
    // one (`has_light`; `pdf_light` with the light's choice).
    reflectance: Soa3,
    cosine_dir: Soa3,
    light_wi: Soa3,
    light_dist: [f32; LANES],
    light_radiance: Soa3,
    pdf_light: [f32; LANES],
    light_delta: [bool; LANES],
    has_light: [bool; LANES],
    // Glass: the relative index and the lobe's number, the refraction's tint in `reflectance`
    // (white but for glTF's clear glass), and whether it gives no sample for `wo` in the surface
    // (1 for glTF's clear glass: `Pbr::sample` gives none there, `Dielectric::sample` a
    // mirror); mirror: the complex index.
    eta: [f32; LANES],
    u_lobe: [f32; LANES],
    none_in_surface: [u32; LANES],
    ior_eta: Soa3,
    ior_k: Soa3,
    // Rough: GGX's alpha, the visible normal's numbers (the first, and the azimuth's cosine
    // and sine); which lanes hold each kind.
    alpha: [f32; LANES],
    u_dir_x: [f32; LANES],
    azimuth: [[f32; LANES]; 2],
    // Compensated conductor: the colour term (the tables are in `LaneTables`).
    ms_scale: Soa3,
    // PBR: the base colour is `reflectance`, the index `eta`, GGX's `alpha_x` `alpha`; the
    // metallic factor, the transmission factor, whether the material transmits (1) or not
    // (0) and whether it is smooth (1), `alpha_y`, the layer table's roughness node (its rows
    // in `LaneTables`), the diffuse lobe's normalisation; whether the frame is turned to an
    // anisotropy direction (1), the direction's cosine and sine, the hit's `dP/dv`.
    metallic: [f32; LANES],
    transmission: [f32; LANES],
    transmits: [u32; LANES],
    smooth: [u32; LANES],
    turned: [u32; LANES],
    turn: [[f32; LANES]; 2],
    dpdv: Soa3,
    alpha_y: [f32; LANES],
    layer_node: [u32; LANES],
    layer_t: [f32; LANES],
    diffuse_norm: [f32; LANES],
    /// The lanes that hold each GGX kind, as bits, at [`ggx_slot`] (the PBR BSDF's at
    /// [`PBR_SLOT`]).
    ggx: [u32; PBR_SLOT + 1],

    // Results: the shadow test (`shadow_radiance` counts where `shadowed`), the bounce (where
    // `scattered`; `delta` where its lobe is a delta), the state after it, whether the path
    // goes on. The flags are `u32` (0 or 1), not `bool`: selecting bytes between kept and new
    // results makes LLVM's cost model keep the GGX loops scalar.
    shadowed: [u32; LANES],
    shadow_o: Soa3,
    shadow_t_max: [f32; LANES],
    shadow_radiance: Soa3,
    scattered: [u32; LANES],
    delta: [u32; LANES],
    n: Soa3,
    wi_world: Soa3,
    origin: Soa3,
    transmitted: [u32; LANES],
    bounce_eta: [f32; LANES],
    prev_pdf: [f32; LANES],
    beta_after: Soa3,
    eta_scale_after: [f32; LANES],
    goes_on: [u32; LANES],
}

/// The albedo tables of each lane's compensated BSDF, copied: the dielectric's for `wo`
/// outside and inside, the conductor's. Lookups in them are gathers, which the GGX loop's SIMD
/// copies vectorise where LLVM sees that they read nothing the loop stores: hence copies (not
/// references to the materials, which it cannot bound), and apart from [`Lanes`] (a distinct
/// object: no store into `Lanes` reaches them).
#[derive(Clone, Copy)]
pub(super) struct LaneTables {
    glass: [[AlbedoTable; LANES]; 2],
    metal: [AlbedoTable; LANES],
    /// The PBR BSDF's layer albedo, the two rows it reads.
    pbr: [LayerRows; LANES],
}

impl LaneTables {
    pub fn new() -> Self {
        LaneTables {
            glass: [[AlbedoTable::ZERO; LANES]; 2],
            metal: [AlbedoTable::ZERO; LANES],
            pbr: [LayerRows::ZERO; LANES],
        }
    }
}

/// A lane's BSDF sample as `land` reads it: `BsdfSample`'s direction (shading frame), weight,
/// density, relative index and whether its lobe is a delta, and whether the BSDF gave one.
#[derive(Clone, Copy)]
struct LaneSample {
    sampled: bool,
    wi: Vec3,
    weight: Rgb,
    pdf: f32,
    eta: f32,
    delta: bool,
}

impl Lanes {
    pub fn new() -> Self {
        let v = Soa3::splat(Vec3::Z);
        let f = [1.0; LANES];
        let b = [false; LANES];
        Lanes {
            kind: [Kind::Diffuse; LANES],
            wo: v,
            p: Soa3::splat(Vec3::ZERO),
            ng: v,
            ns: v,
            dpdu: Soa3::splat(Vec3::X),
            rel: f,
            beta: Soa3::splat(Rgb::ONE),
            eta_scale: f,
            roulette: b,
            u_roulette: f,
            delta_bsdf: [0; LANES],
            reflectance: Soa3::splat(Rgb::ONE),
            cosine_dir: v,
            light_wi: v,
            light_dist: f,
            light_radiance: Soa3::splat(Rgb::ONE),
            pdf_light: f,
            light_delta: b,
            has_light: b,
            eta: f,
            u_lobe: f,
            none_in_surface: [0; LANES],
            ior_eta: Soa3::splat(Vec3::ONE),
            ior_k: Soa3::splat(Vec3::ONE),
            alpha: f,
            u_dir_x: f,
            azimuth: [[0.0; LANES]; 2],
            ms_scale: Soa3::splat(Rgb::ZERO),
            metallic: f,
            transmission: f,
            transmits: [0; LANES],
            smooth: [0; LANES],
            turned: [0; LANES],
            turn: [[0.0; LANES]; 2],
            dpdv: Soa3::splat(Vec3::Y),
            alpha_y: f,
            layer_node: [0; LANES],
            layer_t: f,
            diffuse_norm: f,
            ggx: [0; PBR_SLOT + 1],
            shadowed: [0; LANES],
            shadow_o: v,
            shadow_t_max: f,
            shadow_radiance: Soa3::splat(Rgb::ZERO),
            scattered: [0; LANES],
            delta: [0; LANES],
            n: v,
            wi_world: v,
            origin: v,
            transmitted: [0; LANES],
            bounce_eta: f,
            prev_pdf: f,
            beta_after: Soa3::splat(Rgb::ONE),
            eta_scale_after: f,
            goes_on: [0; LANES],
        }
    }

    /// Stage 1 for lane `i`: the vertex of `path` at `hit`, of the kind [`takes`] found, as
    /// `land` begins it: the emission found at the hit counted, the bounce's numbers drawn
    /// from the path's sampler at the dimensions `land` reads them from, the lane's inputs set
    /// (a compensated BSDF's tables in `tables`).
    #[inline(always)]
    pub fn gather(
        &mut self,
        i: usize,
        scene: &Scene,
        path: &mut Path,
        hit: &SurfaceHit,
        kind: Kind,
        tables: &mut LaneTables,
    ) {
        let shapes = scene.geometry.shapes();
        let material = &scene.materials[shapes[hit.shape as usize].material as usize];
        let depth = path.depth;
        let [u_choice, u_light_x, u_light_y, u_lobe, u_dir_x, u_dir_y, u_roulette] =
            path.bounce_numbers();
        // `land`'s first steps: Beer-Lambert along the segment that met the hit, the emission
        // found there.
        if scene.has_absorption() {
            path.state.absorb(scene, &path.ray, hit);
        }
        let emitted =
            path.state
                .found_emission(scene, &path.ray, Some(hit), light_select_pdf(scene));
        if let Some(c) = emitted {
            path.l += c;
        }
        self.wo.set(i, -path.ray.d);
        self.p.set(i, hit.p);
        self.ng.set(i, hit.ng);
        self.ns.set(i, hit.ns);
        self.dpdu.set(i, hit.dpdu);
        self.rel[i] = scene.geometry.spawn_offset(hit.shape);
        self.beta.set(i, path.state.beta);
        self.eta_scale[i] = path.state.eta_scale;
        self.roulette[i] = depth + 1 >= scene.settings.rr_depth;
        self.u_roulette[i] = u_roulette;
        self.kind[i] = kind;
        if let Some(slot) = kind.slot() {
            self.ggx[slot] |= 1 << i;
        }
        self.delta_bsdf[i] = kind.is_delta() as u32;
        if kind.is_rough() {
            self.u_dir_x[i] = u_dir_x;
            (self.azimuth[0][i], self.azimuth[1][i]) = visible_azimuth(u_dir_y);
        }
        if matches!(kind, Kind::Diffuse | Kind::CompensatedMetal | Kind::Pbr) {
            self.cosine_dir
                .set(i, square_to_cosine_hemisphere(Vec2::new(u_dir_x, u_dir_y)));
        }
        self.u_lobe[i] = u_lobe;
        if kind == Kind::Glass {
            // A dielectric's refraction untinted, sampled in the surface too (glTF's clear
            // glass sets both below).
            self.reflectance.set(i, Rgb::ONE);
            self.none_in_surface[i] = 0;
        }
        if let Material::Pbr(m) = material {
            // `shade`'s shading normal: the normal map's, where there is one.
            self.ns.set(i, m.mapped_normal(hit).unwrap_or(hit.ns));
        }
        match material {
            Material::Diffuse { reflectance } => {
                self.reflectance.set(i, reflectance.eval(hit.uv));
            }
            Material::Conductor { ior, roughness } => {
                self.ior_eta.set(i, ior.eta);
                self.ior_k.set(i, ior.k);
                self.alpha[i] = *roughness;
            }
            Material::Dielectric { eta, roughness } => {
                self.eta[i] = *eta;
                self.alpha[i] = *roughness;
            }
            Material::CompensatedDielectric(c) => {
                self.eta[i] = c.ss.eta;
                self.alpha[i] = c.ss.distribution.alpha_x;
                tables.glass[0][i] = c.outside;
                tables.glass[1][i] = c.inside;
            }
            Material::CompensatedConductor(c) => {
                self.ior_eta.set(i, c.ss.ior.eta);
                self.ior_k.set(i, c.ss.ior.k);
                self.alpha[i] = c.ss.distribution.alpha_x;
                tables.metal[i] = c.albedo;
                self.ms_scale.set(i, c.ms_scale);
            }
            Material::Pbr(m) if kind == Kind::Glass => {
                // Clear smooth glass: the tint of its refraction and its index.
                let pbr = m.bsdf_at(hit.uv, true);
                self.reflectance.set(i, pbr.base_color);
                self.eta[i] = pbr.eta;
                self.none_in_surface[i] = 1;
            }
            Material::Pbr(m) => {
                // `shade`'s BSDF and the turn of its frame.
                self.turned[i] = (m.anisotropy > 0.0) as u32;
                (self.turn[0][i], self.turn[1][i]) = m.anisotropy_direction;
                self.dpdv.set(i, hit.dpdv);
                let pbr = m.bsdf_at(hit.uv, m.has_transmission());
                self.reflectance.set(i, pbr.base_color);
                self.metallic[i] = pbr.metallic;
                self.transmission[i] = pbr.transmission;
                self.transmits[i] = pbr.transmits as u32;
                self.smooth[i] = pbr.smooth as u32;
                self.delta_bsdf[i] = pbr.is_delta() as u32;
                self.eta[i] = pbr.eta;
                self.alpha[i] = pbr.distribution.alpha_x;
                self.alpha_y[i] = pbr.distribution.alpha_y;
                self.layer_node[i] = pbr.layer_node.0 as u32;
                self.layer_t[i] = pbr.layer_node.1;
                self.diffuse_norm[i] = pbr.diffuse_norm;
                tables.pbr[i] = LayerRows::of(pbr.layer, pbr.layer_node);
            }
            Material::Scratched(m) => {
                let Bsdf::Dielectric(base) = m.base_bsdf() else {
                    unreachable!("scratched glass has a smooth dielectric base")
                };
                self.eta[i] = base.eta;
            }
            _ => unreachable!("`takes` took the material"),
        }
        self.has_light[i] = false;
        if self.delta_bsdf[i] == 0 {
            self.light(i, scene, hit, u_choice, Vec2::new(u_light_x, u_light_y));
        }
    }

    /// Next-event estimation's light sample for lane `i` (`direct_light`), where it has one.
    #[inline(always)]
    fn light(&mut self, i: usize, scene: &Scene, hit: &SurfaceHit, u_choice: f32, u_light: Vec2) {
        if scene.lights.is_empty() {
            return;
        }
        let light = chosen_light(scene, u_choice);
        if let Some(ls) = light.sample_li(hit.p, u_light, scene.geometry.shapes()) {
            self.light_wi.set(i, ls.wi);
            self.light_dist[i] = ls.dist;
            self.light_radiance.set(i, ls.radiance);
            self.pdf_light[i] = light_select_pdf(scene) * ls.pdf;
            self.light_delta[i] = ls.delta;
            self.has_light[i] = true;
        }
    }

    /// Stage 2: every lane's vertex, `land`'s operations with its decisions as selects (a
    /// lane [`Self::gather`] did not set computes on stale numbers, and is not scattered): the
    /// diffuse and smooth BSDFs in every lane, then each GGX BSDF of the set `SIMD_GGX` (the
    /// kinds [`takes`] gave) that any lane holds, in every lane, its results kept in the lanes
    /// that hold it.
    #[inline(always)]
    pub fn run<const SIMD_GGX: u32>(&mut self, tables: &LaneTables) {
        for i in 0..LANES {
            self.run_lane(i);
        }
        self.run_ggx_in_lanes::<SIMD_GGX, true, false>(tables);
        self.run_ggx_in_lanes::<SIMD_GGX, false, false>(tables);
        self.run_ggx_in_lanes::<SIMD_GGX, true, true>(tables);
        self.run_ggx_in_lanes::<SIMD_GGX, false, true>(tables);
        if SIMD_GGX & simd_ggx::PBR != 0 && self.ggx[PBR_SLOT] != 0 {
            for i in 0..LANES {
                self.run_pbr_lane(i, tables);
            }
        }
        self.ggx = [0; PBR_SLOT + 1];
    }

    /// [`Self::run`]'s GGX loop for one kind, in every lane, where the set `SIMD_GGX` has it
    /// and any lane holds it.
    #[inline(always)]
    fn run_ggx_in_lanes<const SIMD_GGX: u32, const GLASS: bool, const COMPENSATED: bool>(
        &mut self,
        tables: &LaneTables,
    ) {
        let slot = ggx_slot(GLASS, COMPENSATED);
        if SIMD_GGX & (1 << slot) != 0 && self.ggx[slot] != 0 {
            for i in 0..LANES {
                self.run_ggx_lane::<GLASS, COMPENSATED>(i, tables);
            }
        }
    }

    /// The shading frame of lane `i`'s hit and the direction toward the viewer in it.
    #[inline(always)]
    fn frame(&self, i: usize, transmits: bool) -> (Frame, Vec3) {
        let wo_world = self.wo.get(i);
        let frame = shading_frame_of(
            self.ng.get(i),
            self.ns.get(i),
            self.dpdu.get(i),
            wo_world,
            transmits,
        );
        (frame, frame.to_local(wo_world))
    }

    /// [`Self::run`]'s first loop for lane `i`: the scalar code's functions, in `land`'s order.
    #[inline(always)]
    fn run_lane(&mut self, i: usize) {
        let kind = self.kind[i];
        let transmits = kind == Kind::Glass;
        let (frame, wo) = self.frame(i, transmits);

        // Next-event estimation (`direct_light` with `Diffuse`'s value and density).
        let wi = frame.to_local(self.light_wi.get(i));
        let f = diffuse_eval(self.reflectance.get(i), wo, wi) * wi.z.abs();
        let outcome = self.light_outcome(i, f, diffuse_pdf(wo, wi));

        // The BSDF's sample: `Diffuse::sample`, `Dielectric::sample` (its refraction tinted by
        // `reflectance`: white, or clear glTF glass's base colour) or `Conductor::sample`.
        let cosine_dir = self.cosine_dir.get(i);
        let (r, cos_t, eta_it) = fresnel_f32::dielectric(wo.z, self.eta[i]);
        let mirror = self.u_lobe[i] < r || r >= 1.0;
        let eta_ti = 1.0 / eta_it;
        let fresnel = ConductorIor {
            eta: self.ior_eta.get(i),
            k: self.ior_k.get(i),
        }
        .fresnel(wo.z);
        // (Selects, not a `match` on the kind: a `switch` keeps the loop from vectorising.)
        let (wi, weight, pdf, eta) = if kind == Kind::Diffuse {
            (
                cosine_dir,
                self.reflectance.get(i),
                cosine_hemisphere_pdf(cosine_dir),
                1.0,
            )
        } else if kind == Kind::Mirror {
            (reflect_z(wo), fresnel, 1.0, 1.0)
        } else if mirror {
            (reflect_z(wo), Rgb::ONE, r, 1.0)
        } else {
            (
                Vec3::new(-eta_ti * wo.x, -eta_ti * wo.y, cos_t),
                self.reflectance.get(i) * (eta_ti * eta_ti),
                1.0 - r,
                eta_it,
            )
        };
        // `Diffuse::sample` and `Conductor::sample` give none below the surface (or at a zero
        // density), glTF's clear glass none in it (`wo.z` zero, or NaN).
        let in_surface = wo.z == 0.0 || wo.z.is_nan();
        let sampled =
            (transmits && !(self.none_in_surface[i] != 0 && in_surface)) || !(wo.z <= 0.0);
        let sample = LaneSample {
            sampled,
            wi,
            weight,
            pdf,
            eta,
            delta: kind.is_delta(),
        };
        let bounce = self.bounce_outcome(i, frame, wo, sample);
        self.store(i, true, outcome, bounce);
    }

    /// [`Self::run`]'s GGX loop for lane `i`: the `eval`, `pdf` and `sample` of
    /// [`RoughDielectric`] (`GLASS`) or [`RoughConductor`], or with `COMPENSATED` of
    /// [`CompensatedDielectric`] or [`CompensatedConductor`] (their tables' lookups gathers from
    /// the lane's copies in `tables`), as `land` calls them through `Bsdf`: computed in every
    /// lane, kept where the lane holds that BSDF. Where `land` skips a call (the value without a
    /// light sample, the density where the value is zero or the light a delta), its result is
    /// replaced by what `land` uses instead.
    #[inline(always)]
    fn run_ggx_lane<const GLASS: bool, const COMPENSATED: bool>(
        &mut self,
        i: usize,
        tables: &LaneTables,
    ) {
        let (frame, wo) = self.frame(i, GLASS);
        let distribution = Ggx::isotropic(self.alpha[i]);
        let glass = RoughDielectric {
            eta: self.eta[i],
            distribution,
        };
        let metal = RoughConductor {
            ior: ConductorIor {
                eta: self.ior_eta.get(i),
                k: self.ior_k.get(i),
            },
            distribution,
        };
        let compensated_glass = CompensatedDielectric {
            ss: glass,
            outside: &tables.glass[0][i],
            inside: &tables.glass[1][i],
        };
        let compensated_metal = CompensatedConductor {
            ss: metal,
            albedo: &tables.metal[i],
            ms_scale: self.ms_scale.get(i),
        };

        // Next-event estimation. (`if`s on the constants: compiled away.)
        let wi = frame.to_local(self.light_wi.get(i));
        let (f, pdf) = if GLASS && COMPENSATED {
            (
                compensated_glass.eval(wo, wi),
                compensated_glass.pdf(wo, wi),
            )
        } else if COMPENSATED {
            (
                compensated_metal.eval(wo, wi),
                compensated_metal.pdf(wo, wi),
            )
        } else if GLASS {
            (glass.eval(wo, wi), glass.pdf(wo, wi))
        } else {
            (metal.eval(wo, wi), metal.pdf(wo, wi))
        };
        let outcome = self.light_outcome_of(i, wi, f, pdf);

        // The BSDF's sample.
        let (u_lobe, u_x) = (self.u_lobe[i], self.u_dir_x[i]);
        let azimuth = (self.azimuth[0][i], self.azimuth[1][i]);
        let bs = if GLASS && COMPENSATED {
            compensated_glass.sample_at(wo, u_lobe, u_x, azimuth)
        } else if COMPENSATED {
            compensated_metal.sample_at(wo, u_lobe, self.cosine_dir.get(i), u_x, azimuth)
        } else if GLASS {
            glass.sample_at(wo, u_lobe, u_x, azimuth)
        } else {
            metal.sample_at(wo, u_x, azimuth)
        };
        let keep = self.kind[i] == Kind::ggx(GLASS, COMPENSATED);
        self.store_sampled(i, (frame, wo), outcome, bs, keep);
    }

    /// [`Self::run`]'s PBR loop for lane `i`: [`Pbr`]'s `eval_pdf` and `sample_at` (its
    /// layer table's lookups gathers from the lane's rows in `tables`), as `land` calls
    /// `Pbr`'s through `Bsdf`; kept where the lane holds a PBR BSDF.
    #[inline(always)]
    fn run_pbr_lane(&mut self, i: usize, tables: &LaneTables) {
        let transmits = self.transmits[i] != 0;
        let (frame, _) = self.frame(i, transmits);
        // `shade`'s turn to the anisotropy direction.
        let turn = (self.turn[0][i], self.turn[1][i]);
        let turned = turned_to(frame, turn, self.dpdv.get(i));
        let frame = if self.turned[i] != 0 { turned } else { frame };
        let wo = frame.to_local(self.wo.get(i));
        let pbr = Pbr {
            base_color: self.reflectance.get(i),
            metallic: self.metallic[i],
            transmission: self.transmission[i],
            eta: self.eta[i],
            distribution: Ggx {
                alpha_x: self.alpha[i],
                alpha_y: self.alpha_y[i],
            },
            smooth: self.smooth[i] != 0,
            transmits,
            layer: &tables.pbr[i],
            layer_node: (self.layer_node[i] as usize, self.layer_t[i]),
            diffuse_norm: self.diffuse_norm[i],
        };
        let wi = frame.to_local(self.light_wi.get(i));
        let (f, pdf) = pbr.eval_pdf(wo, wi);
        let outcome = self.light_outcome_of(i, wi, f, pdf);
        let azimuth = (self.azimuth[0][i], self.azimuth[1][i]);
        let (u_lobe, cosine_dir) = (self.u_lobe[i], self.cosine_dir.get(i));
        let bs = pbr.sample_at(wo, u_lobe, cosine_dir, self.u_dir_x[i], azimuth);
        let keep = self.kind[i] == Kind::Pbr;
        self.store_sampled(i, (frame, wo), outcome, bs, keep);
    }

    /// Next-event estimation's outcome for lane `i` from its BSDF's value `f` (without the
    /// cosine) and density `pdf` toward the light sample `wi` (shading frame), as `land` uses
    /// them: no value without a light sample, no density where the value is zero or the light
    /// a delta.
    #[inline(always)]
    fn light_outcome_of(&self, i: usize, wi: Vec3, f: Rgb, pdf: f32) -> LightOutcome {
        let f = f * wi.z.abs();
        let f = if self.has_light[i] { f } else { Rgb::ZERO };
        let pdf = if f != Rgb::ZERO && !self.light_delta[i] {
            pdf
        } else {
            0.0
        };
        self.light_outcome(i, f, pdf)
    }

    /// Lane `i`'s results, where `keep`, from next-event estimation's `outcome` and the
    /// BSDF's sample `bs` (`None`: the path ends) in the shading frame `frame` (`wo` toward the
    /// viewer).
    #[inline(always)]
    fn store_sampled(
        &mut self,
        i: usize,
        (frame, wo): (Frame, Vec3),
        outcome: LightOutcome,
        bs: Option<BsdfSample>,
        keep: bool,
    ) {
        let sample = match bs {
            Some(BsdfSample {
                wi,
                weight,
                pdf,
                eta,
                delta,
                ..
            }) => LaneSample {
                sampled: true,
                wi,
                weight,
                pdf,
                eta,
                delta,
            },
            None => LaneSample {
                sampled: false,
                wi: Vec3::Z,
                weight: Rgb::ZERO,
                pdf: 0.0,
                eta: 1.0,
                delta: false,
            },
        };
        let bounce = self.bounce_outcome(i, frame, wo, sample);
        self.store(i, keep, outcome, bounce);
    }

    /// Next-event estimation's shadow test for lane `i` (`direct_light`), from the BSDF's
    /// value times the cosine `f` and its density `pdf_bsdf` toward the light sample.
    #[inline(always)]
    fn light_outcome(&self, i: usize, f: Rgb, pdf_bsdf: f32) -> LightOutcome {
        let (p, light_wi) = (self.p.get(i), self.light_wi.get(i));
        let pdf_light = self.pdf_light[i];
        let shadow_o = offset_origin_by(p, self.ng.get(i), light_wi, self.rel[i]);
        let w = if self.light_delta[i] {
            1.0
        } else {
            power_heuristic(pdf_light, pdf_bsdf)
        };
        LightOutcome {
            shadowed: self.has_light[i] && f != Rgb::ZERO,
            o: shadow_o,
            t_max: shadow_t_max(self.light_dist[i], shadow_o, p),
            radiance: self.beta.get(i) * f * self.light_radiance.get(i) * (w / pdf_light),
        }
    }

    /// The bounce of lane `i` from its BSDF's sample `s` (in the shading frame `frame`, `wo`
    /// toward the viewer), as `land` makes it: the path ends at a sample of no density or
    /// weight; `PathState::scatter`, the spawned ray, `PathState::survives_roulette`.
    #[inline(always)]
    fn bounce_outcome(&self, i: usize, frame: Frame, wo: Vec3, s: LaneSample) -> BounceOutcome {
        let scattered = s.sampled && s.pdf > 0.0 && s.weight != Rgb::ZERO;
        let wi_world = frame.to_world(s.wi);
        let beta = self.beta.get(i) * s.weight;
        let eta_scale = self.eta_scale[i] * (s.eta * s.eta);
        let q = survival_probability(beta, eta_scale);
        let survives = self.u_roulette[i] < q;
        BounceOutcome {
            scattered,
            delta: s.delta,
            n: frame.n,
            wi_world,
            origin: offset_origin_by(self.p.get(i), self.ng.get(i), wi_world, self.rel[i]),
            transmitted: s.wi.z * wo.z < 0.0,
            eta: s.eta,
            pdf: s.pdf,
            beta: if self.roulette[i] { beta / q } else { beta },
            eta_scale,
            goes_on: scattered && (!self.roulette[i] || survives),
        }
    }

    /// Lane `i`'s results, where `keep` (a select, not a branch: the loops store in every
    /// lane).
    #[inline(always)]
    fn store(&mut self, i: usize, keep: bool, light: LightOutcome, bounce: BounceOutcome) {
        #[inline(always)]
        fn pick<T>(keep: bool, new: T, old: T) -> T {
            if keep {
                new
            } else {
                old
            }
        }
        self.shadowed[i] = pick(keep, light.shadowed as u32, self.shadowed[i]);
        self.shadow_o
            .set(i, pick(keep, light.o, self.shadow_o.get(i)));
        self.shadow_t_max[i] = pick(keep, light.t_max, self.shadow_t_max[i]);
        let radiance = pick(keep, light.radiance, self.shadow_radiance.get(i));
        self.shadow_radiance.set(i, radiance);
        self.scattered[i] = pick(keep, bounce.scattered as u32, self.scattered[i]);
        self.delta[i] = pick(keep, bounce.delta as u32, self.delta[i]);
        self.n.set(i, pick(keep, bounce.n, self.n.get(i)));
        self.wi_world
            .set(i, pick(keep, bounce.wi_world, self.wi_world.get(i)));
        self.origin
            .set(i, pick(keep, bounce.origin, self.origin.get(i)));
        self.transmitted[i] = pick(keep, bounce.transmitted as u32, self.transmitted[i]);
        self.bounce_eta[i] = pick(keep, bounce.eta, self.bounce_eta[i]);
        self.prev_pdf[i] = pick(keep, bounce.pdf, self.prev_pdf[i]);
        self.beta_after
            .set(i, pick(keep, bounce.beta, self.beta_after.get(i)));
        self.eta_scale_after[i] = pick(keep, bounce.eta_scale, self.eta_scale_after[i]);
        self.goes_on[i] = pick(keep, bounce.goes_on as u32, self.goes_on[i]);
    }

    /// Stage 3 for lane `i`: its results into `path` (the next ray and the state after the
    /// bounce, where it goes on) and the shadow test it leaves, as `land` leaves them.
    /// Returns whether the path goes on.
    #[inline(always)]
    pub fn scatter<const DIFFERENTIALS: bool>(
        &self,
        i: usize,
        scene: &Scene,
        path: &mut Path,
        hit: &SurfaceHit,
        worker: &mut Worker,
        shadow: &mut Option<ShadowTest>,
    ) -> bool {
        worker.rays += 1;
        if self.shadowed[i] != 0 {
            worker.rays += 1;
            *shadow = Some(ShadowTest {
                ray: Ray {
                    o: self.shadow_o.get(i),
                    d: self.light_wi.get(i),
                    t_max: self.shadow_t_max[i],
                },
                radiance: self.shadow_radiance.get(i),
            });
        }
        if self.scattered[i] == 0 {
            return false;
        }
        // (`PathState::scatter`.)
        let delta = self.delta[i] != 0;
        path.state.beta = self.beta_after.get(i);
        path.state.eta_scale = self.eta_scale_after[i];
        path.state.specular = delta || self.delta_bsdf[i] != 0;
        path.state.prev_pdf = self.prev_pdf[i];
        if DIFFERENTIALS {
            let transmitted = self.transmitted[i] != 0;
            path.push_bounce(
                &scene.geometry,
                DeferredBounce {
                    hit: *hit,
                    n: self.n.get(i),
                    d_in: path.ray.d,
                    wi: self.wi_world.get(i),
                    delta,
                    transmitted,
                    eta: if transmitted {
                        1.0 / self.bounce_eta[i]
                    } else {
                        1.0
                    },
                },
            );
        }
        path.origin_depth = f32::INFINITY;
        path.ray = Ray::new(self.origin.get(i), self.wi_world.get(i));
        path.depth += 1;
        self.goes_on[i] != 0
    }
}

/// Next-event estimation's results for a lane (`Lanes::light_outcome`).
struct LightOutcome {
    shadowed: bool,
    o: Vec3,
    t_max: f32,
    radiance: Rgb,
}

/// A lane's bounce (`Lanes::bounce_outcome`): the new ray, the state after it.
struct BounceOutcome {
    scattered: bool,
    delta: bool,
    n: Vec3,
    wi_world: Vec3,
    origin: Vec3,
    transmitted: bool,
    eta: f32,
    pdf: f32,
    beta: Rgb,
    eta_scale: f32,
    goes_on: bool,
}

/// `Diffuse::eval` for the reflectance `reflectance`.
#[inline(always)]
fn diffuse_eval(reflectance: Rgb, wo: Vec3, wi: Vec3) -> Rgb {
    crate::render::bsdf::Diffuse::new(reflectance).eval(wo, wi)
}

/// `Diffuse::pdf`.
#[inline(always)]
fn diffuse_pdf(wo: Vec3, wi: Vec3) -> f32 {
    crate::render::bsdf::Diffuse::new(Rgb::ONE).pdf(wo, wi)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::geometry::SurfaceHit;
    use crate::render::integrator::path::camera_sample;
    use crate::render::scene::Overrides;

    /// Diffuse (textured and plain), glass (a smooth mesh and a sphere), gold, rough glass and
    /// rough copper, plain and compensated (`multiscatter = true`), glTF's BSDF (`pbr`: plastic,
    /// metal, a textured mix, glass, smooth, anisotropic, normal-mapped), a diffuse and a smooth
    /// glTF sphere that glow, under every kind of light the lanes sample: a rectangle and
    /// spheres that emit, a point light (delta) and a constant sky (left to BSDF sampling).
    const SCENE: &str = r#"
[render]
width = 24
height = 16
max_depth = 10
rr_depth = 2
sampler = "SAMPLER"

[camera]
position = [0.0, 1.6, 5.0]
look_at = [0.0, 0.6, 0.0]
fov = 45.0

[materials.glass]
type = "dielectric"
ior = 1.5

[materials.dense]
type = "dielectric"
ior = 2.4

[materials.floor]
type = "diffuse"
reflectance = { type = "checkerboard", color0 = [0.8, 0.7, 0.6], color1 = [0.1, 0.2, 0.1], scale = 8.0 }

[materials.white]
type = "diffuse"
reflectance = [0.9, 0.85, 0.8]

[materials.gold]
type = "conductor"
preset = "gold"

[materials.frosted]
type = "dielectric"
ior = 1.5
roughness = 0.3

[materials.brushed]
type = "conductor"
preset = "copper"
roughness = 0.15

[materials.milky]
type = "dielectric"
ior = 1.4
roughness = 0.6
multiscatter = true

[materials.worn]
type = "conductor"
preset = "gold"
roughness = 0.5
multiscatter = true

[materials.plastic]
type = "pbr"
base_color = [0.7, 0.1, 0.05]
metallic = 0.0
roughness = 0.5

[materials.bronze]
type = "pbr"
base_color = [0.9, 0.6, 0.3]
metallic = 1.0
roughness = 0.3

# Half its cells a rough mix of metal and plastic, half smooth metal (a delta BSDF).
[materials.mixed]
type = "pbr"
base_color = { type = "checkerboard", color0 = [0.2, 0.5, 0.8], color1 = [0.9, 0.9, 0.9], scale = 6.0 }
metallic = 1.0
roughness = 1.0
metallic_roughness = { type = "checkerboard", color0 = [0.0, 0.6, 0.3], color1 = [0.0, 0.0, 1.0], scale = 6.0 }

# Opaque, yet absorbing behind its surface: seen from behind (the panel), its vertices are
# attenuated first.
[materials.tinted]
type = "pbr"
base_color = [0.6, 0.6, 0.6]
metallic = 0.0
roughness = 0.4
attenuation_color = [0.5, 0.7, 0.9]
attenuation_distance = 0.5

# Clear smooth glass, tinted and normal-mapped: taken as a dielectric.
[materials.bottle]
type = "pbr"
base_color = [0.6, 0.9, 0.7]
metallic = 0.0
roughness = 0.0
transmission = 1.0
ior = 1.45
normal_map = { type = "checkerboard", color0 = [0.65, 0.45, 0.9], color1 = [0.4, 0.6, 0.95], scale = 5.0 }

# Rough glass, and a rough mix of metal, plastic and glass, normal-mapped: taken with glTF's
# BSDF.
[materials.haze]
type = "pbr"
base_color = [0.9, 0.8, 0.7]
metallic = 0.0
roughness = 0.35
transmission = 1.0

[materials.veil]
type = "pbr"
base_color = [0.7, 0.8, 0.9]
metallic = 0.2
roughness = 0.5
transmission = 0.6
ior = 1.7
normal_map = { type = "checkerboard", color0 = [0.3, 0.55, 0.9], color1 = [0.6, 0.7, 0.85], scale = 4.0 }

# Smooth plastic, and a smooth mix of metal, plastic and glass: delta lobes beside a diffuse
# one; smooth metal: a delta BSDF.
[materials.lacquer]
type = "pbr"
base_color = [0.1, 0.3, 0.7]
metallic = 0.0
roughness = 0.0

[materials.pane]
type = "pbr"
base_color = [0.8, 0.7, 0.5]
metallic = 0.3
roughness = 0.0
transmission = 0.5
ior = 1.6

[materials.chrome]
type = "pbr"
base_color = [0.9, 0.9, 0.95]
metallic = 1.0
roughness = 0.0

# Anisotropic: taken with glTF's BSDF in a turned frame.
[materials.satin]
type = "pbr"
base_color = [0.8, 0.8, 0.8]
metallic = 1.0
roughness = 0.3
anisotropy = 0.7

[[shapes]]
type = "teapot"
material = "glass"
subdivisions = 4
transform = [{ scale = 0.4 }, { translate = [-0.7, 0.0, 0.0] }]

[[shapes]]
type = "sphere"
center = [0.8, 0.5, 0.3]
radius = 0.5
material = "dense"

[[shapes]]                       # white, and it glows
type = "sphere"
center = [0.1, 0.3, 1.2]
radius = 0.3
material = "white"
emission = [0.8, 0.7, 0.6]

[[shapes]]
type = "sphere"
center = [2.3, 1.3, 0.8]
radius = 0.45
material = "lacquer"
emission = [0.3, 0.4, 0.6]

[[shapes]]
type = "sphere"
center = [2.4, 0.4, 1.2]
radius = 0.35
material = "chrome"

[[shapes]]
type = "sphere"
center = [-2.2, 1.4, 0.4]
radius = 0.45
material = "pane"

[[shapes]]
type = "sphere"
center = [-1.1, 0.45, 1.5]
radius = 0.45
material = "gold"

[[shapes]]
type = "sphere"
center = [0.9, 0.35, 1.4]
radius = 0.35
material = "frosted"

[[shapes]]
type = "sphere"
center = [-0.2, 0.25, 2.0]
radius = 0.25
material = "brushed"

[[shapes]]
type = "sphere"
center = [0.5, 0.3, 2.4]
radius = 0.3
material = "milky"

[[shapes]]
type = "sphere"
center = [-0.8, 0.3, 2.5]
radius = 0.3
material = "worn"

[[shapes]]
type = "sphere"
center = [1.5, 0.3, 2.2]
radius = 0.3
material = "plastic"

[[shapes]]
type = "sphere"
center = [-1.6, 0.35, 0.2]
radius = 0.35
material = "bronze"

[[shapes]]
type = "sphere"
center = [0.0, 0.9, -0.9]
radius = 0.45
material = "mixed"

[[shapes]]
type = "sphere"
center = [1.9, 0.45, -0.2]
radius = 0.45
material = "satin"

[[shapes]]
type = "sphere"
center = [0.35, 0.9, 1.6]
radius = 0.28
material = "bottle"

[[shapes]]
type = "sphere"
center = [-0.45, 0.9, 1.0]
radius = 0.28
material = "haze"

[[shapes]]
type = "sphere"
center = [1.2, 0.9, 0.9]
radius = 0.28
material = "veil"

[[shapes]]
type = "rectangle"
material = "tinted"
transform = [{ scale = 0.5 }, { rotate = { axis = [0, 1, 0], angle = 180 } }, { translate = [-1.5, 1.3, -1.5] }]

[[shapes]]
type = "rectangle"
material = "floor"
transform = [{ scale = 4.0 }, { rotate = { axis = [1, 0, 0], angle = -90 } }]

[[shapes]]
type = "rectangle"
emission = [6.0, 5.0, 4.0]
transform = [{ scale = 0.6 }, { rotate = { axis = [1, 0, 0], angle = 90 } }, { translate = [-1.0, 3.0, 1.0] }]

[[shapes]]
type = "sphere"
center = [1.5, 2.0, -1.0]
radius = 0.3
emission = [3.0, 3.0, 3.0]

[[lights]]
type = "point"
position = [0.5, 2.5, 2.0]
intensity = 4.0

[environment]
type = "constant"
radiance = [0.2, 0.25, 0.3]
"#;

    fn scene(sampler: &str) -> Scene {
        let text = SCENE.replace("SAMPLER", sampler);
        let file = std::path::Path::new("lanes.toml");
        Scene::parse(
            &text,
            file,
            std::path::Path::new("."),
            &Overrides::default(),
        )
        .unwrap()
    }

    fn ray_bits(r: &Ray) -> [u32; 7] {
        let [a, b, c] = r.o.to_array().map(f32::to_bits);
        let [d, e, f] = r.d.to_array().map(f32::to_bits);
        [a, b, c, d, e, f, r.t_max.to_bits()]
    }

    /// Everything of a path a vertex changes, as bits.
    fn path_bits(p: &Path) -> Vec<u32> {
        let mut v = ray_bits(&p.ray).to_vec();
        v.extend(p.l.to_array().map(f32::to_bits));
        v.extend(p.state.beta.to_array().map(f32::to_bits));
        v.extend([
            p.state.eta_scale.to_bits(),
            p.state.specular as u32,
            p.state.prev_pdf.to_bits(),
            p.depth,
            p.origin_depth.to_bits(),
        ]);
        v
    }

    fn shadow_bits(s: &Option<ShadowTest>) -> Option<([u32; 7], [u32; 3])> {
        s.as_ref()
            .map(|s| (ray_bits(&s.ray), s.radiance.to_array().map(f32::to_bits)))
    }

    /// Each vertex the lanes take, run in lane `i` (every lane in turn, the others holding the
    /// vertices before it), gives `land`'s path, shadow test, ray count and ending bit for bit,
    /// over whole paths of every pixel: both samplers, each copy's set of GGX kinds in SIMD
    /// lanes ([`simd_ggx`]: those kinds in every lane, the lane's kept; the others not taken).
    #[test]
    fn lane_vertex_equals_land() {
        fn takes_in(set: u32, scene: &Scene, hit: &SurfaceHit, path: &Path) -> Option<Kind> {
            let (depth, d) = (path.depth, path.ray.d);
            match set {
                simd_ggx::ALL => takes::<{ simd_ggx::ALL }>(scene, hit, depth, d),
                simd_ggx::AVX2 => takes::<{ simd_ggx::AVX2 }>(scene, hit, depth, d),
                simd_ggx::NONE => takes::<{ simd_ggx::NONE }>(scene, hit, depth, d),
                _ => unreachable!(),
            }
        }
        fn run_in(set: u32, lanes: &mut Lanes, tables: &LaneTables) {
            match set {
                simd_ggx::ALL => lanes.run::<{ simd_ggx::ALL }>(tables),
                simd_ggx::AVX2 => lanes.run::<{ simd_ggx::AVX2 }>(tables),
                simd_ggx::NONE => lanes.run::<{ simd_ggx::NONE }>(tables),
                _ => unreachable!(),
            }
        }
        let sets = [simd_ggx::ALL, simd_ggx::AVX2, simd_ggx::NONE];
        for (sampler, set) in ["sobol", "independent"]
            .into_iter()
            .flat_map(|sampler| sets.map(|set| (sampler, set)))
        {
            let scene = scene(sampler);
            let (mut taken, mut glass, mut mirror, mut shadowed, mut ended) = (0, 0, 0, 0, 0);
            let (mut rough_glass, mut rough_metal) = (0, 0);
            let (mut compensated_glass, mut compensated_metal, mut pbr) = (0, 0, 0);
            let (mut absorbed, mut clear_pbr, mut rough_pbr_glass, mut mapped) = (0, 0, 0, 0);
            let (mut anisotropic, mut smooth_pbr, mut delta_pbr, mut glowing) = (0, 0, 0, 0);
            let (mut lanes, mut tables) = (Lanes::new(), LaneTables::new());
            let mut lane = 0;
            for y in 0..16 {
                for x in 0..24 {
                    let index = y as u64 * 24 + x as u64;
                    for s in 0..4 {
                        let camera = camera_sample::<false>(&scene, (x, y), index, s);
                        let (mut a, mut b) = (Path::new(camera.clone()), Path::new(camera));
                        let (mut wa, mut wb) = (Worker::default(), Worker::default());
                        loop {
                            let hit = scene.geometry.intersect(&a.ray);
                            let kind = hit.as_ref().and_then(|h| takes_in(set, &scene, h, &a));
                            // Behind an absorbing surface: `land` attenuates the path first.
                            let attenuated = hit.as_ref().is_some_and(|h| {
                                let m = scene.geometry.shapes()[h.shape as usize].material;
                                scene.materials.get(m as usize).is_some_and(|m| {
                                    m.absorption().is_some() && a.ray.d.dot(h.ng) > 0.0
                                })
                            });
                            let la = a.land::<false, true>(&scene, hit, &mut wa);
                            let (goes_on, shadow) = if let Some(kind) = kind {
                                let hit: SurfaceHit = hit.unwrap();
                                lanes.gather(lane, &scene, &mut b, &hit, kind, &mut tables);
                                run_in(set, &mut lanes, &tables);
                                let mut shadow = None;
                                let goes_on = lanes.scatter::<false>(
                                    lane,
                                    &scene,
                                    &mut b,
                                    &hit,
                                    &mut wb,
                                    &mut shadow,
                                );
                                taken += 1;
                                glass += (kind == Kind::Glass) as u32;
                                mirror += (kind == Kind::Mirror) as u32;
                                rough_glass += (kind == Kind::RoughGlass) as u32;
                                rough_metal += (kind == Kind::RoughMetal) as u32;
                                compensated_glass += (kind == Kind::CompensatedGlass) as u32;
                                compensated_metal += (kind == Kind::CompensatedMetal) as u32;
                                pbr += (kind == Kind::Pbr) as u32;
                                absorbed += attenuated as u32;
                                let m = scene.geometry.shapes()[hit.shape as usize].material;
                                let material = &scene.materials[m as usize];
                                let is_pbr = matches!(material, Material::Pbr(_));
                                clear_pbr += (kind == Kind::Glass && is_pbr) as u32;
                                rough_pbr_glass +=
                                    (kind == Kind::Pbr && material.has_transmission()) as u32;
                                mapped += matches!(material, Material::Pbr(p) if p.normal_map.is_some())
                                    as u32;
                                anisotropic += matches!(material, Material::Pbr(p) if p.anisotropy > 0.0)
                                    as u32;
                                if let (Kind::Pbr, Material::Pbr(p)) = (kind, material) {
                                    let bsdf = p.bsdf_at(hit.uv, p.has_transmission());
                                    smooth_pbr += bsdf.smooth as u32;
                                    delta_pbr += bsdf.is_delta() as u32;
                                }
                                let shape = &scene.geometry.shapes()[hit.shape as usize];
                                glowing += shape.area_light.is_some() as u32;
                                lane = (lane + 1) % LANES;
                                (goes_on, shadow)
                            } else {
                                let lb = b.land::<false, true>(&scene, hit, &mut wb);
                                (lb.goes_on, lb.shadow)
                            };
                            assert_eq!(la.goes_on, goes_on, "pixel ({x}, {y}) sample {s}");
                            assert_eq!(shadow_bits(&la.shadow), shadow_bits(&shadow));
                            assert_eq!(wa.rays, wb.rays);
                            shadowed += shadow.is_some() as u32;
                            if !goes_on {
                                ended += kind.is_some() as u32;
                                break;
                            }
                            assert_eq!(path_bits(&a), path_bits(&b), "pixel ({x}, {y}) sample {s}");
                        }
                    }
                }
            }
            // Every kind of vertex, light samples, and paths ended by roulette or absorption.
            let rough = rough_glass + rough_metal + compensated_glass + compensated_metal + pbr;
            let diffuse = taken - glass - mirror - rough;
            assert!(
                diffuse > 200 && glass > 200 && mirror > 50,
                "{diffuse} {glass} {mirror}"
            );
            // Each GGX kind taken where the set has it (at least this many vertices), never
            // where it has not.
            for (count, bit, least) in [
                (rough_glass, simd_ggx::ROUGH_GLASS, 100),
                (rough_metal, simd_ggx::ROUGH_METAL, 40),
                (compensated_glass, simd_ggx::COMPENSATED_GLASS, 40),
                (compensated_metal, simd_ggx::COMPENSATED_METAL, 40),
                (pbr, simd_ggx::PBR, 50),
            ] {
                if set & bit != 0 {
                    assert!(count > least, "{sampler} {set:b}: {count} of kind {bit:b}");
                } else {
                    assert_eq!(count, 0, "{sampler} {set:b}: kind {bit:b} taken");
                }
            }
            assert!(shadowed > 200 && ended > 50, "{shadowed} {ended}");
            // Vertices attenuated before they shade and rough transmitting glTF materials
            // (taken with glTF's BSDF), and clear glTF glass taken as a dielectric in every set.
            if set & simd_ggx::PBR != 0 {
                assert!(absorbed > 20, "{sampler}: {absorbed} vertices attenuated");
                assert!(
                    rough_pbr_glass > 100,
                    "{sampler}: {rough_pbr_glass} rough transmitting glTF vertices"
                );
                assert!(
                    anisotropic > 30,
                    "{sampler}: {anisotropic} anisotropic vertices"
                );
                // Smooth glTF BSDFs: with a diffuse lobe, and delta ones.
                assert!(
                    smooth_pbr - delta_pbr > 100 && delta_pbr > 30,
                    "{sampler}: {smooth_pbr} smooth glTF vertices, {delta_pbr} delta"
                );
            }
            // Vertices on a shape that emits, their emission counted first.
            assert!(glowing > 30, "{sampler}: {glowing} vertices that glow");
            // Normal-mapped glTF materials (the clear glass in every set).
            assert!(
                mapped > 50,
                "{sampler}: {mapped} normal-mapped glTF vertices"
            );
            assert!(
                clear_pbr > 50,
                "{sampler}: {clear_pbr} clear glTF glass vertices"
            );
        }
    }
}
