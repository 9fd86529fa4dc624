//! Unidirectional path tracing with next-event estimation and multiple importance sampling
//! (Veach 1997, power heuristic with beta = 2), Russian roulette and a maximum depth; the
//! structure follows pbrt-v4's `PathIntegrator` and Mitsuba 3's `path` integrator.
//!
//! * **Depth** follows Mitsuba's `max_depth`: the longest path, counted in segments from the
//!   camera. `max_depth = 1` shows only emitters seen directly, `2` adds direct lighting, and
//!   so on; 0 means unlimited (Mitsuba's -1).
//! * **Russian roulette** from depth `rr_depth` (Mitsuba's default 5) with survival
//!   probability `min(max(beta * eta_scale), 0.95)`, where `eta_scale` undoes the radiance
//!   scaling of refraction (pbrt-v4).
//! * **Shading normals**: opaque BSDFs get their frame flipped to `wo`'s side of the geometric
//!   normal; then, if `wo` lies on the other side of the shading normal than of the geometric
//!   one, the shading normal is bent toward the geometric normal until `wo` is (just) on the
//!   correct side, so interpolated normals never produce black pixels (the artefact pbrt and
//!   Mitsuba handle by flipping or by geometric-side checks).
//! * **Ray differentials** start at the camera and are carried to every hit
//!   (`shading::spawn_differentials`); their texture-space footprint reaches the material in
//!   the [`ShadingContext`]. They are worked out lazily ([`PathDifferentials`]): a bounce is
//!   recorded, and the records are turned into differentials only when a later hit reads its
//!   footprint (the scratched material seen from outside), with the same operations, so the
//!   image is the same as if every bounce were worked out. In a scene where no material
//!   reads the footprint ([`Material::reads_footprint`]) they are skipped altogether (the
//!   footprint fields are then zero), which changes no pixel either.
//! * **Speed**: the render loop is compiled three times, for AVX-512 (x86-64-v4), AVX2 + FMA
//!   (x86-64-v3) and portable, the widest the CPU runs chosen at run time ([`LoopCopy`]), with
//!   traversal and shading inlined into it; all three give the same image bit for bit
//!   ([`render_with`]; Rust never contracts `a * b + c` into an FMA).
//! * **Determinism**: each pixel sample draws from its own Sobol stream
//!   (`sampler::PixelSampler`), tiles are rendered in parallel by rayon and written to fixed
//!   places, so the image does not depend on the thread count.
//! * A sample whose radiance is not finite (NaN or infinite) is counted as black, and counted.

// `!(x > 0.0)` is meant: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use crate::layers::CoverageCache;
use crate::math::{Frame, Ray, RayDifferential, Rgb, Vec2, Vec3};
use crate::render::bsdf::{Bsdf, BsdfSample};
use crate::render::film::Image;
use crate::render::geometry::{Geometry, SurfaceHit, PACKET};
use crate::render::material::{HitView, Material};
use crate::render::sampler::{PixelSampler, LOBE_DIM};
use crate::render::scene::{Scene, NO_MATERIAL};
use crate::render::shading::{
    footprint_dp, hit_context, spawn_differentials, PixelHit, ShadingContext,
};
use crate::sampling::power_heuristic;
use arrayvec::ArrayVec;
use rayon::prelude::*;
use std::mem::MaybeUninit;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

/// Side of a square tile of pixels, the unit of parallel work.
pub const TILE: u32 = 16;

/// Counters of one render.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderStats {
    /// Camera samples traced (pixels x spp).
    pub samples: u64,
    /// Rays traced: closest-hit and shadow rays.
    pub rays: u64,
    /// Samples whose radiance was not finite and was dropped.
    pub nonfinite: u64,
    /// Wall time in seconds.
    pub seconds: f64,
    /// The compiled copy of the render loop that ran.
    pub copy: LoopCopy,
}

impl RenderStats {
    pub fn samples_per_second(&self) -> f64 {
        self.samples as f64 / self.seconds.max(1e-9)
    }
    pub fn rays_per_second(&self) -> f64 {
        self.rays as f64 / self.seconds.max(1e-9)
    }
}

/// What every pixel of one render shares: whether paths carry ray differentials (only when a
/// material reads the footprint), and which of its samples are traced (`first..end`).
#[derive(Clone, Copy)]
struct Pass {
    differentials: bool,
    samples: (u32, u32),
}

/// What one render worker owns: its counters, summed at the end of each tile, and its
/// scratch-coverage caches, handed to the materials it shades.
#[derive(Default)]
struct Worker {
    rays: u64,
    nonfinite: u64,
    coverage: CoverageCache,
}

/// Offset a ray origin off the surface at `p` (geometric normal `ng`) toward the side `dir`
/// leaves to, by a distance scaled with the magnitude of `p` to stay above float error.
#[inline]
pub fn offset_origin(p: Vec3, ng: Vec3, dir: Vec3) -> Vec3 {
    crate::render::geometry::offset_origin_by(p, ng, dir, crate::render::geometry::OFFSET)
}

/// The shading normals at the starts of a delta bounce's offset rays
/// ([`spawn_differentials`]): the bounce's normal `n` (the frame's, which may be flipped to
/// `wo`'s side or guarded) plus the change of the surface's normal field from the hit to
/// `p + dpdx` and `p + dpdy` ([`Geometry::shading_normal_steps`]). `None` on flat surfaces.
/// Out of line: the render loop calls it only on shapes with curved normals
/// ([`Geometry::has_curved_normals`]), so scenes of flat glass do not carry its code.
#[inline(never)]
pub fn offset_normals(
    geometry: &Geometry,
    hit: &SurfaceHit,
    n: Vec3,
    dpdx: Vec3,
    dpdy: Vec3,
) -> Option<(Vec3, Vec3)> {
    let [dnx, dny] = geometry.shading_normal_steps(hit, [dpdx, dpdy])?;
    let side = if n.dot(hit.ns) < 0.0 { -1.0 } else { 1.0 };
    // The change's component along `n` only changes the normal's length (the interpolated
    // normal is shorter inside a triangle): dropping it keeps `n + dn` unit to second order
    // in the step, with no square root.
    let bent = |dn: Vec3| n + side * (dn - dn.dot(n) * n);
    Some((bent(dnx), bent(dny)))
}

/// A bounce whose spawned ray differentials are not worked out yet ([`PathDifferentials`]):
/// what [`footprint_dp`], [`offset_normals`] and [`spawn_differentials`] read of it.
#[derive(Clone, Copy)]
struct DeferredBounce {
    hit: SurfaceHit,
    /// The normal of the frame the hit was shaded in (flipped or guarded).
    n: Vec3,
    /// Direction of the ray that arrived, and of the one that left.
    d_in: Vec3,
    wi: Vec3,
    delta: bool,
    /// Whether the ray left through the surface (refracted) rather than reflected.
    transmitted: bool,
    /// `n_incident / n_transmitted` along the path (1 for a reflection).
    eta: f32,
}

impl DeferredBounce {
    /// The differentials of the ray leaving this bounce, from those of the ray that arrived:
    /// the footprint on the hit's tangent plane, the offset rays' normals on curved surfaces
    /// (delta bounces only) and the bent offset rays.
    #[inline(always)]
    fn spawn(&self, geometry: &Geometry, rd: &RayDifferential) -> RayDifferential {
        let (dpdx, dpdy) = footprint_dp(&self.hit, rd);
        let normals = if self.delta && geometry.has_curved_normals(self.hit.shape) {
            offset_normals(geometry, &self.hit, self.n, dpdx, dpdy)
        } else {
            None
        };
        spawn_differentials(
            self.hit.p, dpdx, dpdy, self.d_in, rd, self.n, normals, self.wi, self.delta, self.eta,
        )
    }
}

/// The ray differentials of one path, worked out lazily: each bounce is recorded, and the
/// records are turned into differentials only when a later hit reads its footprint (the
/// scratched material seen from outside), so the bounces after a path's last such hit (most of
/// a path through glass: the hits inside, the floor, the sky) cost a copy instead of the
/// bending. The same operations run in the same order as when every bounce is worked out at
/// once, so every footprint, and the image, is the same bit for bit (test
/// `deferred_differentials_equal_eager_ones`); the setting-1 teapot renders 7 % faster so.
/// The path's chain of delta bounces ([`PixelHit::chain`]), read at the same hits, is folded
/// in the same way, instead of a SplitMix64 round at every bounce.
struct PathDifferentials {
    /// Differentials of the ray that arrived at the first pending bounce (of the path's current
    /// ray when none is pending).
    rd: RayDifferential,
    /// The chain of delta bounces up to the first pending bounce; `None` once a bounce was not
    /// a delta one.
    chain: Option<u64>,
    /// The first `len` entries are initialised.
    pending: [MaybeUninit<DeferredBounce>; PathDifferentials::CAPACITY],
    len: usize,
    /// The camera ray's film position minus its pixel's centre ([`PixelHit::offset`]).
    offset: Vec2,
}

impl PathDifferentials {
    /// Bounces kept pending at most; a longer run is worked out as it fills up. 16: paths of
    /// the usual `max_depth = 16` never fill it, so no bounce is worked out that no hit reads
    /// (8 costs 50 instructions a sample in flushes on long paths inside glass, glass teapot
    /// carrying differentials).
    const CAPACITY: usize = 16;

    #[inline(always)]
    fn new(rd: RayDifferential, offset: Vec2) -> Self {
        PathDifferentials {
            rd,
            chain: Some(0),
            pending: [const { MaybeUninit::uninit() }; Self::CAPACITY],
            len: 0,
            offset,
        }
    }

    /// Record a bounce (the ray leaving it is the path's current ray).
    #[inline(always)]
    fn push(&mut self, geometry: &Geometry, bounce: DeferredBounce) {
        if self.len == Self::CAPACITY {
            self.resolve(geometry);
        }
        self.pending[self.len].write(bounce);
        self.len += 1;
    }

    /// The differentials of the path's current ray, and its chain of delta bounces (`None`
    /// after a non-delta bounce).
    #[inline(always)]
    fn resolve(&mut self, geometry: &Geometry) -> (RayDifferential, Option<u64>) {
        for entry in &self.pending[..self.len] {
            // SAFETY: the first `len` entries were written by `push`.
            let bounce = unsafe { entry.assume_init_ref() };
            self.rd = bounce.spawn(geometry, &self.rd);
            self.chain = self
                .chain
                .filter(|_| bounce.delta)
                .map(|chain| PixelHit::chain_after(chain, bounce.hit.shape, bounce.transmitted));
        }
        self.len = 0;
        (self.rd, self.chain)
    }
}

/// The shading context at `hit` seen from `wo_world` and the BSDF the material presents there
/// ([`Material::shade`], with every part of the context the material may read): for tests and
/// debugging views of the footprint.
pub fn shade<'a>(
    material: &'a Material,
    hit: &SurfaceHit,
    rd: &RayDifferential,
    wo_world: Vec3,
    u_layer: f32,
) -> (ShadingContext, Bsdf<'a>) {
    let view = HitView {
        wo: wo_world,
        rd: Some(rd),
        u_layer: Some(u_layer),
        pixel: None,
        origin_depth: f32::INFINITY,
    };
    let (frame, bsdf) = material.shade(hit, view, &mut CoverageCache::new());
    let ctx = hit_context(hit, Some(rd), frame, wo_world, u_layer, None);
    (ctx, bsdf)
}

/// The shading contexts along the camera ray through film position `film` (pinhole centre of
/// the lens), following delta bounces (the first lobe a BSDF samples with `u = 0.5`) for up to
/// `max_hits` hits; stops after the first non-delta BSDF. For tests and debugging views of the
/// footprint (e.g. the scratch masks in the scratched material's tests).
pub fn trace_contexts(scene: &Scene, film: Vec2, max_hits: usize) -> Vec<ShadingContext> {
    let (mut ray, mut rd) = scene.camera.generate_ray(film, Vec2::splat(0.5));
    let mut out = Vec::new();
    while out.len() < max_hits {
        let Some(hit) = scene.geometry.intersect(&ray) else {
            break;
        };
        let shape = &scene.geometry.shapes()[hit.shape as usize];
        if shape.material == NO_MATERIAL {
            break;
        }
        let wo_world = -ray.d;
        let (ctx, bsdf) = shade(
            &scene.materials[shape.material as usize],
            &hit,
            &rd,
            wo_world,
            0.5,
        );
        out.push(ctx);
        let wo = ctx.frame.to_local(wo_world);
        let Some(bs) = bsdf.sample(wo, 0.5, Vec2::splat(0.5)) else {
            break;
        };
        if !bs.delta {
            break;
        }
        let wi = ctx.frame.to_world(bs.wi);
        let transmitted = bs.wi.z * wo.z < 0.0;
        let bounce = DeferredBounce {
            hit,
            n: ctx.frame.n,
            d_in: ray.d,
            wi,
            delta: true,
            transmitted,
            eta: if transmitted { 1.0 / bs.eta } else { 1.0 },
        };
        rd = bounce.spawn(&scene.geometry, &rd);
        ray = Ray::new(
            scene.geometry.spawn_origin(hit.p, hit.ng, hit.shape, wi),
            wi,
        );
    }
    out
}

/// Render the whole image. `progress` is called (from worker threads) with the number of
/// camera samples each finished tile traced.
pub fn render(scene: &Scene, progress: &(dyn Fn(u64) + Sync)) -> (Image, RenderStats) {
    render_with(scene, progress, Simd::Auto)
}

/// Which compiled copies of the render loop a render may use (the image does not depend on it).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Simd {
    /// The widest copy the CPU runs ([`LoopCopy::available`]), capped by the environment
    /// ([`LoopCopy::env_cap`]).
    Auto,
    /// At most the AVX2 copy: for tests that check the copies give the same image, and for
    /// benchmarks.
    Avx2,
    /// Always the portable copy (baseline x86-64 / any other target).
    Portable,
}

/// A compiled copy of the render loop (traversal, shading, sampling, all inlined into it), from
/// the narrowest to the widest.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum LoopCopy {
    /// Baseline x86-64 (SSE2) or any other target.
    Portable,
    /// AVX2, FMA, BMI1/2, LZCNT, POPCNT (x86-64-v3).
    Avx2,
    /// The AVX2 set plus AVX-512 F/VL/BW/DQ/CD (x86-64-v4): the same 256-bit box tests, but 32
    /// vector registers, so the big render loop spills less (on an AMD Zen 4, smooth glass
    /// 2.6-5.7 % faster, scratched glass -2 to +1 %: `BENCHMARKS.md`, "Design findings"). LLVM
    /// also uses 512-bit moves and a few 512-bit compares in it, which lower the clock of
    /// Intel's first AVX-512 server cores (Skylake-SP); not measured there (`STRIAE_SIMD=avx2`
    /// caps the choice).
    Avx512,
}

impl LoopCopy {
    /// The widest copy this CPU runs.
    pub fn available() -> LoopCopy {
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::is_x86_feature_detected as has;
            let avx2 = has!("avx2")
                && has!("fma")
                && has!("bmi1")
                && has!("bmi2")
                && has!("lzcnt")
                && has!("popcnt");
            let avx512 = has!("avx512f")
                && has!("avx512vl")
                && has!("avx512bw")
                && has!("avx512dq")
                && has!("avx512cd");
            match (avx2, avx512) {
                (true, true) => LoopCopy::Avx512,
                (true, false) => LoopCopy::Avx2,
                _ => LoopCopy::Portable,
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            LoopCopy::Portable
        }
    }

    /// The widest copy the environment allows: `STRIAE_SIMD` = `avx512` (the default), `avx2`
    /// or `portable`; `STRIAE_PORTABLE` set means `portable`. An error names a bad value (the
    /// CLI reports it; [`Self::chosen`] ignores it).
    pub fn env_cap() -> Result<LoopCopy, String> {
        if std::env::var_os("STRIAE_PORTABLE").is_some() {
            return Ok(LoopCopy::Portable);
        }
        match std::env::var("STRIAE_SIMD") {
            Err(std::env::VarError::NotPresent) => Ok(LoopCopy::Avx512),
            Ok(v) if v == "avx512" => Ok(LoopCopy::Avx512),
            Ok(v) if v == "avx2" => Ok(LoopCopy::Avx2),
            Ok(v) if v == "portable" => Ok(LoopCopy::Portable),
            Ok(v) => Err(format!(
                "environment variable STRIAE_SIMD = \"{v}\": expected \"avx512\", \"avx2\" or \"portable\""
            )),
            Err(_) => Err("environment variable STRIAE_SIMD is not valid UTF-8".into()),
        }
    }

    /// The copy a render with `simd` runs on this CPU.
    pub fn chosen(simd: Simd) -> LoopCopy {
        let cap = match simd {
            Simd::Portable => LoopCopy::Portable,
            Simd::Avx2 => LoopCopy::Avx2,
            Simd::Auto => Self::env_cap().unwrap_or(LoopCopy::Avx512),
        };
        cap.min(Self::available())
    }

    /// The name the CLI prints: `portable`, `AVX2` or `AVX-512`.
    pub fn name(self) -> &'static str {
        match self {
            LoopCopy::Portable => "portable",
            LoopCopy::Avx2 => "AVX2",
            LoopCopy::Avx512 => "AVX-512",
        }
    }
}

/// [`render`] with a choice of compiled render loop; the image does not depend on it.
pub fn render_with(
    scene: &Scene,
    progress: &(dyn Fn(u64) + Sync),
    simd: Simd,
) -> (Image, RenderStats) {
    let (w, h) = scene.camera.resolution();
    render_into(scene, Image::new(w, h), progress, None, simd)
}

/// [`render`] with the film allocated before the first sample: where the allocator refuses it,
/// an error naming `what` (the flag or key that set the size) instead of an abort.
pub fn try_render(
    scene: &Scene,
    progress: &(dyn Fn(u64) + Sync),
    what: &str,
) -> Result<(Image, RenderStats), crate::memory::MemoryError> {
    let (w, h) = scene.camera.resolution();
    let image = Image::try_new(w, h, what)?;
    Ok(render_into(scene, image, progress, None, Simd::Auto))
}

/// What [`try_render_observed`] calls with each finished tile: its index and its pixels, row by
/// row.
pub type TileObserver<'a> = dyn Fn(u32, &[Rgb]) + Sync + 'a;

/// [`try_render`] that also hands each finished tile's final pixels (its index, [`tile_rect`],
/// and its pixels row by row, the values the image gets) to `on_tile`, from the worker thread
/// that rendered it: a live preview reads the film as it fills without changing how any pixel
/// is computed, so the image is bit for bit [`try_render`]'s.
pub fn try_render_observed(
    scene: &Scene,
    progress: &(dyn Fn(u64) + Sync),
    on_tile: &TileObserver<'_>,
    what: &str,
) -> Result<(Image, RenderStats), crate::memory::MemoryError> {
    let (w, h) = scene.camera.resolution();
    let image = Image::try_new(w, h, what)?;
    Ok(render_into(
        scene,
        image,
        progress,
        Some(on_tile),
        Simd::Auto,
    ))
}

/// The render of every tile of `image`'s film, placed into it; `on_tile`, where given, as in
/// [`try_render_observed`].
fn render_into(
    scene: &Scene,
    mut image: Image,
    progress: &(dyn Fn(u64) + Sync),
    on_tile: Option<&TileObserver<'_>>,
    simd: Simd,
) -> (Image, RenderStats) {
    let tiles: Vec<u32> = (0..tile_count(image.width, image.height)).collect();
    let spp = scene.settings.spp;
    // The tile's means, divided as below: the values the image gets.
    let observe = |tile: u32, sums: &[Rgb]| {
        if let Some(on_tile) = on_tile {
            let mut means = sums.to_vec();
            for p in &mut means {
                *p /= spp as f32;
            }
            on_tile(tile, &means);
        }
    };
    let (mut pixels, stats) = render_tile_sums_observed(
        scene,
        &tiles,
        0..spp,
        progress,
        &observe,
        &AtomicBool::new(false),
        simd,
    )
    .expect("a render nothing cancels runs to the end");
    for p in pixels.iter_mut().flatten() {
        *p /= spp as f32;
    }
    for (&tile, px) in tiles.iter().zip(&pixels) {
        place_tile(&mut image, tile, px);
    }
    (image, stats)
}

/// Refuses a render of `pixels` pixels of the loaded `scene` (a part's, or the whole film's)
/// that would not fit: [`crate::render::film::BYTES_PER_PIXEL`] a pixel, on top of what the
/// scene holds ([`crate::render::scene::explicit::BYTES_PER_TRIANGLE`] a BVH primitive: its
/// meshes, explicit grooves and BVH), which counts against `max_memory` only as the machine's
/// headroom already excludes it. `what` names the flag or key that set the size.
pub fn check_memory(
    scene: &Scene,
    pixels: u64,
    what: &str,
    max_memory: Option<u64>,
) -> Result<(), crate::memory::MemoryError> {
    let held = scene.geometry.primitive_count() as u64
        * crate::render::scene::explicit::BYTES_PER_TRIANGLE as u64;
    crate::memory::check_more(
        what,
        pixels.saturating_mul(crate::render::film::BYTES_PER_PIXEL),
        held,
        max_memory,
    )
}

/// The number of [`TILE`] x [`TILE`] tiles of a `w x h` film (the last row and column may be
/// cut short), numbered row by row from the top left: the renderer's unit of work.
pub fn tile_count(w: u32, h: u32) -> u32 {
    w.div_ceil(TILE) * h.div_ceil(TILE)
}

/// The pixels `[x0, y0, x1, y1)` of tile `tile` of a `w x h` film.
pub fn tile_rect(w: u32, h: u32, tile: u32) -> [u32; 4] {
    let tiles_x = w.div_ceil(TILE);
    let (x0, y0) = ((tile % tiles_x) * TILE, (tile / tiles_x) * TILE);
    [x0, y0, (x0 + TILE).min(w), (y0 + TILE).min(h)]
}

/// Copy the pixels of tile `tile` ([`render_tiles`]'s order: row by row) into `image`.
pub fn place_tile(image: &mut Image, tile: u32, pixels: &[Rgb]) {
    let [x0, y0, x1, _] = tile_rect(image.width, image.height, tile);
    let tw = x1 - x0;
    for (i, &p) in pixels.iter().enumerate() {
        let (x, y) = (x0 + i as u32 % tw, y0 + i as u32 / tw);
        image.pixels[(y * image.width + x) as usize] = p;
    }
}

/// A render stopped by its caller ([`render_tiles`]' `cancel`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[error("the render was cancelled")]
pub struct Cancelled;

/// The pixels of the tiles `tiles` of the film ([`tile_rect`]), each row by row, in the order
/// given: the one render loop of whole renders ([`render_with`]) and of parts of an image
/// (`parts`). A pixel's value depends only on the scene and the pixel (its samples draw from
/// the pixel's own streams; the workers' caches never change a value), so the pixels of a
/// tile are the same whichever other tiles are rendered with it, and by which thread.
/// `progress` is called (from worker threads) with the camera samples each finished tile
/// traced; once `cancel` is set, the tiles not started yet are skipped and the result is
/// [`Cancelled`].
pub fn render_tiles(
    scene: &Scene,
    tiles: &[u32],
    progress: &(dyn Fn(u64) + Sync),
    cancel: &AtomicBool,
    simd: Simd,
) -> Result<(Vec<Vec<Rgb>>, RenderStats), Cancelled> {
    let spp = scene.settings.spp;
    let (mut pixels, stats) = render_tile_sums(scene, tiles, 0..spp, progress, cancel, simd)?;
    for p in pixels.iter_mut().flatten() {
        *p /= spp as f32;
    }
    Ok((pixels, stats))
}

/// [`render_tiles`] of the samples `samples` (a range of `0..spp`) of each pixel only: each
/// pixel's sum of those samples' radiance (`f32`, added in sample order, non-finite samples
/// dropped), not divided by anything. With `0..spp`, the sum [`render_tiles`] divides by the
/// spp. A sample's radiance depends on the pixel's earlier samples only through the pixel's
/// scratch-coverage footprints (`layers::CoverageCache::of_pixel`), which a range starting
/// after 0 takes from its own first samples.
pub fn render_tile_sums(
    scene: &Scene,
    tiles: &[u32],
    samples: std::ops::Range<u32>,
    progress: &(dyn Fn(u64) + Sync),
    cancel: &AtomicBool,
    simd: Simd,
) -> Result<(Vec<Vec<Rgb>>, RenderStats), Cancelled> {
    render_tile_sums_observed(scene, tiles, samples, progress, &|_, _| {}, cancel, simd)
}

/// [`render_tile_sums`] that hands each finished tile's sums (its index and pixels, row by row)
/// to `on_tile` on the worker thread that rendered it, before `progress` counts it.
fn render_tile_sums_observed(
    scene: &Scene,
    tiles: &[u32],
    samples: std::ops::Range<u32>,
    progress: &(dyn Fn(u64) + Sync),
    on_tile: &TileObserver<'_>,
    cancel: &AtomicBool,
    simd: Simd,
) -> Result<(Vec<Vec<Rgb>>, RenderStats), Cancelled> {
    let copy = LoopCopy::chosen(simd);
    let start = std::time::Instant::now();
    let (w, h) = scene.camera.resolution();
    let rays = AtomicU64::new(0);
    let nonfinite = AtomicU64::new(0);
    let n = samples.len() as u64;
    let pass = Pass {
        differentials: scene.materials.iter().any(Material::reads_footprint),
        samples: (samples.start, samples.end),
    };
    // One worker per thread, and every tile a job of its own (`with_max_len(1)`): rayon's
    // adaptive splitting otherwise hands each thread runs of tiles that cannot be stolen once
    // begun, and where the costly tiles bunch up (a teapot in the middle of the film) one thread
    // can finish 0.1-0.3 s before the other (the built-in scene at 2 threads: 1.97 s wall for
    // 3.61 CPU-s, against 1.79 s balanced). The image does not depend on which worker renders a
    // tile.
    let workers: Vec<std::sync::Mutex<Worker>> = (0..rayon::current_num_threads())
        .map(|_| Default::default())
        .collect();
    let pixels: Vec<Option<Vec<Rgb>>> = tiles
        .par_iter()
        .with_max_len(1)
        .map(|&tile| {
            if cancel.load(Ordering::Relaxed) {
                return None;
            }
            let thread = rayon::current_thread_index().unwrap_or(0) % workers.len();
            let mut worker = workers[thread].lock().unwrap_or_else(|e| e.into_inner());
            let worker = &mut *worker;
            let out = render_tile(scene, tile_rect(w, h, tile), pass, copy, worker);
            rays.fetch_add(std::mem::take(&mut worker.rays), Ordering::Relaxed);
            nonfinite.fetch_add(std::mem::take(&mut worker.nonfinite), Ordering::Relaxed);
            on_tile(tile, &out);
            progress(out.len() as u64 * n);
            Some(out)
        })
        .collect();
    let pixels: Vec<Vec<Rgb>> = pixels.into_iter().collect::<Option<_>>().ok_or(Cancelled)?;
    let stats = RenderStats {
        samples: pixels.iter().map(|p| p.len() as u64).sum::<u64>() * n,
        rays: rays.into_inner(),
        nonfinite: nonfinite.into_inner(),
        seconds: start.elapsed().as_secs_f64(),
        copy,
    };
    Ok((pixels, stats))
}

/// The pixels of the tile `[x0, y0, x1, y1)` (row by row), by the render loop's `copy`
/// ([`LoopCopy::chosen`], which the CPU supports). The copies give the same image bit for bit:
/// Rust never fuses a multiply and an add on its own, so the wider instructions compute the
/// same IEEE operations.
fn render_tile(
    scene: &Scene,
    rect: [u32; 4],
    pass: Pass,
    copy: LoopCopy,
    worker: &mut Worker,
) -> Vec<Rgb> {
    // One compiled loop per case (with and without differentials), each with only its own
    // state to keep in registers.
    #[cfg(target_arch = "x86_64")]
    match copy {
        // SAFETY: `copy` is at most `LoopCopy::available()`, so the CPU has the features.
        LoopCopy::Avx512 => unsafe {
            return if pass.differentials {
                render_tile_avx512::<true>(scene, rect, pass.samples, worker)
            } else {
                render_tile_avx512::<false>(scene, rect, pass.samples, worker)
            };
        },
        // SAFETY: as above.
        LoopCopy::Avx2 => unsafe {
            return if pass.differentials {
                render_tile_avx2::<true>(scene, rect, pass.samples, worker)
            } else {
                render_tile_avx2::<false>(scene, rect, pass.samples, worker)
            };
        },
        LoopCopy::Portable => {}
    }
    let _ = copy;
    if pass.differentials {
        render_tile_body::<true>(scene, rect, pass.samples, worker)
    } else {
        render_tile_body::<false>(scene, rect, pass.samples, worker)
    }
}

/// Items compiled for the AVX2 copy of the render loop ([`LoopCopy::Avx2`]; `x86_64` only):
/// to be called only where the CPU has its instruction sets. Exported so that tools run code as
/// the render loop does (the `trace_rays` example) without repeating the feature lists.
#[macro_export]
macro_rules! loop_copy_avx2 {
    ($($item:item)*) => {$(
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2,fma,bmi1,bmi2,lzcnt,popcnt")]
        $item
    )*};
}

/// Items compiled for the AVX-512 copy of the render loop ([`LoopCopy::Avx512`]), as
/// [`loop_copy_avx2!`].
#[macro_export]
macro_rules! loop_copy_avx512 {
    ($($item:item)*) => {$(
        #[cfg(target_arch = "x86_64")]
        #[target_feature(
            enable = "avx2,fma,bmi1,bmi2,lzcnt,popcnt,avx512f,avx512vl,avx512bw,avx512dq,avx512cd"
        )]
        $item
    )*};
}

/// `$name`: [`render_tile_body`] compiled by `$copy` ([`loop_copy_avx2!`] or
/// [`loop_copy_avx512!`]) for the instruction sets of one copy of the render loop
/// ([`LoopCopy`]).
macro_rules! render_loop_copy {
    ($copy:ident, $name:ident) => {
        $copy! {
            unsafe fn $name<const DIFFERENTIALS: bool>(
                scene: &Scene,
                rect: [u32; 4],
                samples: (u32, u32),
                worker: &mut Worker,
            ) -> Vec<Rgb> {
                render_tile_body::<DIFFERENTIALS>(scene, rect, samples, worker)
            }
        }
    };
}

render_loop_copy!(loop_copy_avx2, render_tile_avx2);
render_loop_copy!(loop_copy_avx512, render_tile_avx512);

/// The tile's pixels' sums of the samples `samples`, with (`DIFFERENTIALS`,
/// `pass.differentials`) or without ray differentials.
#[inline(always)]
fn render_tile_body<const DIFFERENTIALS: bool>(
    scene: &Scene,
    [x0, y0, x1, y1]: [u32; 4],
    samples: (u32, u32),
    worker: &mut Worker,
) -> Vec<Rgb> {
    let mut out = Vec::with_capacity(((x1 - x0) * (y1 - y0)) as usize);
    for y in y0..y1 {
        for x in x0..x1 {
            out.push(render_pixel::<DIFFERENTIALS>(scene, x, y, samples, worker));
        }
    }
    out
}

/// A camera ray's closest hit, found before its path runs (in a packet), or not yet.
#[derive(Clone, Copy)]
enum CameraHit {
    Traced(Option<SurfaceHit>),
    Untraced,
}

/// One sample of a pixel up to its camera ray.
struct CameraSample {
    /// The sample's random numbers, past the camera's dimensions.
    sampler: PixelSampler,
    ray: Ray,
    /// The ray's differentials (along the ray without `DIFFERENTIALS`).
    rd: RayDifferential,
    /// The film position minus the pixel's centre, in pixels ([`PixelHit::offset`]; zero
    /// without `DIFFERENTIALS`).
    offset: Vec2,
}

/// Sample `s` of pixel `(x, y)` (index `pixel_index`) up to its camera ray. (Forced inline,
/// with what it calls, into the render loop's copies: out of line it runs without their
/// instruction sets, and the sampler with it, 10 % slower.)
#[inline(always)]
fn camera_sample<const DIFFERENTIALS: bool>(
    scene: &Scene,
    (x, y): (u32, u32),
    pixel_index: u64,
    s: u32,
) -> CameraSample {
    let mut sampler =
        PixelSampler::with_kind(scene.settings.sampler, pixel_index, s, scene.settings.seed);
    let in_pixel = sampler.next_2d();
    let film = Vec2::new(x as f32, y as f32) + in_pixel;
    let u_lens = sampler.next_2d();
    let (ray, rd, offset) = if DIFFERENTIALS {
        let (ray, rd) = scene.camera.generate_ray(film, u_lens);
        (ray, rd, in_pixel - Vec2::splat(0.5))
    } else {
        let ray = scene.camera.generate_ray_only(film, u_lens);
        (ray, RayDifferential::along(&ray), Vec2::ZERO)
    };
    CameraSample {
        sampler,
        ray,
        rd,
        offset,
    }
}

/// Pixels with at least this many samples trace their camera rays in packets (through a
/// pinhole): at 4 spp packets are 4-7 % faster, at 2 spp neither faster nor slower (glass
/// teapot and smooth close-up, whole process).
const PACKET_MIN_SPP: u32 = 4;

/// The sum of the samples `first..end` of pixel `(x, y)` (box filter: uniform positions in the
/// pixel), added in sample order; divided by the spp, the pixel's value when they are all of
/// them. From [`PACKET_MIN_SPP`] samples on, in chunks of up to [`PACKET`]: a chunk's camera
/// rays are traced together (`Geometry::intersect_coherent`), then its paths run one after
/// another, in sample order. The hits are the same, so the image is too.
#[inline(always)]
fn render_pixel<const DIFFERENTIALS: bool>(
    scene: &Scene,
    x: u32,
    y: u32,
    (start, end): (u32, u32),
    worker: &mut Worker,
) -> Rgb {
    let (w, _) = scene.camera.resolution();
    let pixel_index = y as u64 * w as u64 + x as u64;
    worker.coverage.start_pixel();
    let mut sum = Rgb::ZERO;
    let mut add = |l: Rgb, worker: &mut Worker| {
        if l.is_finite() {
            sum += l;
        } else {
            worker.nonfinite += 1;
        }
    };
    // (A thin lens's rays share no origin: no packet.)
    if end - start < PACKET_MIN_SPP || !scene.camera.is_pinhole() {
        for s in start..end {
            let mut sample = camera_sample::<DIFFERENTIALS>(scene, (x, y), pixel_index, s);
            let l = radiance::<DIFFERENTIALS>(scene, &mut sample, CameraHit::Untraced, worker);
            add(l, worker);
        }
        return sum;
    }
    // (`ArrayVec`s: only what a chunk holds is written.)
    let mut samples = ArrayVec::<CameraSample, PACKET>::new();
    let mut rays = ArrayVec::<Ray, PACKET>::new();
    let mut hits = ArrayVec::<Option<SurfaceHit>, PACKET>::new();
    let mut first = start;
    while first < end {
        let n = (end - first).min(PACKET as u32);
        samples.clear();
        rays.clear();
        for s in first..first + n {
            let sample = camera_sample::<DIFFERENTIALS>(scene, (x, y), pixel_index, s);
            rays.push(sample.ray);
            samples.push(sample);
        }
        scene.geometry.intersect_coherent(&rays, &mut hits);
        for (sample, hit) in samples.iter_mut().zip(&hits) {
            let l = radiance::<DIFFERENTIALS>(scene, sample, CameraHit::Traced(*hit), worker);
            add(l, worker);
        }
        first += n;
    }
    sum
}

/// Radiance arriving at the camera along a camera sample's ray (one path sample), whose closest
/// hit is `camera_hit` where traced beforehand (in a packet). With `DIFFERENTIALS` false the
/// ray differentials are neither used nor updated (no material of the scene reads them).
#[inline(always)]
fn radiance<const DIFFERENTIALS: bool>(
    scene: &Scene,
    camera: &mut CameraSample,
    camera_hit: CameraHit,
    worker: &mut Worker,
) -> Rgb {
    let CameraSample {
        sampler,
        ray,
        rd,
        offset,
    } = camera;
    let mut ray = *ray;
    let settings = &scene.settings;
    let shapes = scene.geometry.shapes();
    let n_lights = scene.lights.len();
    let light_select_pdf = if n_lights > 0 {
        1.0 / n_lights as f32
    } else {
        0.0
    };
    let max_depth = if settings.max_depth == 0 {
        u32::MAX
    } else {
        settings.max_depth
    };

    let mut l = Rgb::ZERO;
    let mut path = PathState::new();
    let mut differentials = PathDifferentials::new(*rd, *offset);

    let mut depth = 0u32;
    // How far below the surface the ray began, where it went on from below one
    // (`BsdfSample::from`).
    let mut origin_depth = f32::INFINITY;
    loop {
        sampler.start_bounce(depth);
        worker.rays += 1;
        let hit = match camera_hit {
            CameraHit::Traced(hit) if depth == 0 => hit,
            _ => scene.geometry.intersect(&ray),
        };
        if scene.has_absorption() {
            if let Some(h) = hit.as_ref() {
                path.absorb(scene, &ray, h);
            }
        }
        if let Some(c) = path.found_emission(scene, &ray, hit.as_ref(), light_select_pdf) {
            l += c;
        }
        let Some(hit) = hit else {
            break;
        };
        let shape = &shapes[hit.shape as usize];
        let wo_world = -ray.d;
        // Paths of at most `max_depth` segments: the next vertex would make depth + 2. A shape
        // without a material (a pure emitter) absorbs everything.
        if depth + 2 > max_depth || shape.material == NO_MATERIAL {
            break;
        }

        // Shading frame and the material's BSDF.
        let (frame, bsdf) = shade_hit::<DIFFERENTIALS>(
            scene,
            &hit,
            Arrival {
                wo: wo_world,
                origin_depth,
            },
            depth,
            sampler,
            &mut differentials,
            worker,
        );
        let wo = frame.to_local(wo_world);

        // Next-event estimation.
        if !bsdf.is_delta() && n_lights > 0 {
            let vertex = Vertex {
                hit: &hit,
                frame,
                wo,
                bsdf: &bsdf,
                beta: path.beta,
            };
            if let Some(c) = direct_light(scene, &vertex, sampler, worker) {
                l += c;
            }
        }

        // Continue the path by sampling the BSDF.
        sampler.seek(depth, LOBE_DIM);
        let u_lobe = sampler.next_1d();
        let u_dir = sampler.next_2d();
        let Some(bs) = bsdf.sample(wo, u_lobe, u_dir) else {
            break;
        };
        if !(bs.pdf > 0.0) || bs.weight == Rgb::ZERO {
            break;
        }
        let wi_world = frame.to_world(bs.wi);
        path.scatter(&bs, bsdf.is_delta());
        if DIFFERENTIALS {
            let transmitted = bs.wi.z * wo.z < 0.0;
            differentials.push(
                &scene.geometry,
                DeferredBounce {
                    hit,
                    n: frame.n,
                    d_in: ray.d,
                    wi: wi_world,
                    delta: bs.delta,
                    transmitted,
                    eta: if transmitted { 1.0 / bs.eta } else { 1.0 },
                },
            );
        }
        let origin = match bs.from {
            // The path left a groove's wall below the surface (traced glass walls seen from
            // inside): on from there, toward the surface beside the groove, where the next hit
            // looks the scratches up again.
            Some(from) => {
                origin_depth = -from.z;
                let p = hit.p + frame.to_world(from);
                scene.geometry.spawn_origin(p, hit.ng, hit.shape, wo_world)
            }
            None => {
                origin_depth = f32::INFINITY;
                scene
                    .geometry
                    .spawn_origin(hit.p, hit.ng, hit.shape, wi_world)
            }
        };
        ray = Ray::new(origin, wi_world);

        depth += 1;
        if depth >= settings.rr_depth && !path.survives_roulette(sampler) {
            break;
        }
    }
    l
}

/// What a path carries from vertex to vertex: its throughput `beta`, the product of the
/// squared relative indices it crossed (to keep Russian roulette independent of radiance
/// scaling at refraction), and what the MIS weight of the next emitter hit needs.
struct PathState {
    beta: Rgb,
    eta_scale: f32,
    /// The last bounce was a delta lobe (the camera counts as one): emitters hit count fully.
    specular: bool,
    /// The BSDF sampling pdf of the last bounce.
    prev_pdf: f32,
}

impl PathState {
    #[inline(always)]
    fn new() -> Self {
        PathState {
            beta: Rgb::ONE,
            eta_scale: 1.0,
            specular: true,
            prev_pdf: 0.0,
        }
    }

    /// The MIS weight of emission found by BSDF sampling ([`emission_weight`]).
    #[inline(always)]
    fn emission_weight(&self, light_pdf: impl FnOnce() -> f32) -> f32 {
        emission_weight(self.specular, self.prev_pdf, light_pdf)
    }

    /// Emission the path finds along `ray`, times its throughput and MIS-weighted against
    /// light sampling: the environment's where it escapes (`hit` is `None`), an area light's
    /// where it hits one.
    #[inline(always)]
    fn found_emission(
        &self,
        scene: &Scene,
        ray: &Ray,
        hit: Option<&SurfaceHit>,
        light_select_pdf: f32,
    ) -> Option<Rgb> {
        let Some(hit) = hit else {
            let env = scene.environment()?;
            let le = env.eval(ray.d);
            let w = self.emission_weight(|| light_select_pdf * env.light_pdf(ray.d));
            return Some(self.beta * le * w);
        };
        let shapes = scene.geometry.shapes();
        let light = &scene.lights[shapes[hit.shape as usize].area_light? as usize];
        let le = light.emitted(hit.ng, -ray.d);
        if le == Rgb::ZERO {
            return None;
        }
        let w = self.emission_weight(|| {
            light_select_pdf * light.area_pdf(shapes, ray.o, hit.t, ray.d, hit.ng)
        });
        Some(self.beta * le * w)
    }

    /// Beer-Lambert absorption along the segment `ray` travelled to `hit`: where it ends on the
    /// back side (w.r.t. `ng`) of a surface whose material absorbs
    /// ([`crate::render::material::Material::absorption`]), it ran inside that object, and the
    /// throughput is multiplied by `exp(-sigma_a t)`, `t` the segment's length. Nested media are
    /// not tracked: a segment inside an absorbing object that ends on another object's front
    /// side is not attenuated.
    #[inline(never)]
    fn absorb(&mut self, scene: &Scene, ray: &Ray, hit: &SurfaceHit) {
        let material = scene.geometry.shapes()[hit.shape as usize].material;
        if material == NO_MATERIAL || !(ray.d.dot(hit.ng) > 0.0) {
            return;
        }
        if let Some(sigma_a) = scene.materials[material as usize].absorption() {
            let t = hit.t * ray.d.length();
            self.beta *= (-sigma_a * t).exp();
        }
    }

    /// Continue through the sampled bounce `bs`, from a BSDF that skipped light sampling
    /// ([`Bsdf::is_delta`]) or not.
    #[inline(always)]
    fn scatter(&mut self, bs: &BsdfSample, skipped_light_sampling: bool) {
        self.beta *= bs.weight;
        self.eta_scale *= bs.eta * bs.eta;
        self.specular = bs.delta || skipped_light_sampling;
        self.prev_pdf = bs.pdf;
    }

    /// Russian roulette: survive with probability `q = min(max(beta eta_scale), 0.95)` and
    /// divide the throughput by it.
    #[inline(always)]
    fn survives_roulette(&mut self, sampler: &mut PixelSampler) -> bool {
        let q = (self.beta * self.eta_scale).max_element().min(0.95);
        if !(sampler.next_1d() < q) {
            return false;
        }
        self.beta /= q;
        true
    }
}

/// The MIS weight of emission a path found by BSDF sampling: 1 after a delta bounce (and at the
/// camera), else the power heuristic of the BSDF's pdf `prev_pdf` against light sampling's,
/// `light_pdf()` (light choice included).
#[inline(always)]
fn emission_weight(specular: bool, prev_pdf: f32, light_pdf: impl FnOnce() -> f32) -> f32 {
    if specular {
        1.0
    } else {
        power_heuristic(prev_pdf, light_pdf())
    }
}

/// How the ray that made a hit arrived: the direction toward the viewer (world) and how far
/// below the surface it began ([`crate::render::shading::ShadingContext::origin_depth`]).
#[derive(Clone, Copy)]
struct Arrival {
    wo: Vec3,
    origin_depth: f32,
}

/// The shading frame and the BSDF of the material at `hit` (not a pure emitter), for the ray
/// `arrival` at bounce `depth`, with what the material reads of the hit worked out only where
/// it reads it: `u_layer`, the footprint, and the chain of delta bounces that led here.
#[inline(always)]
fn shade_hit<'a, const DIFFERENTIALS: bool>(
    scene: &'a Scene,
    hit: &SurfaceHit,
    arrival: Arrival,
    depth: u32,
    sampler: &mut PixelSampler,
    differentials: &mut PathDifferentials,
    worker: &mut Worker,
) -> (Frame, Bsdf<'a>) {
    let Arrival {
        wo: wo_world,
        origin_depth,
    } = arrival;
    let material = &scene.materials[scene.geometry.shapes()[hit.shape as usize].material as usize];
    // `u_layer`: dimension 0 of the bounce's block, drawn only where the material reads it
    // (the scratched material, not glass seen from inside). Where it only breaks ties between
    // crossing scratches it is hashed: the block's first Sobol set (light choice and position)
    // is computed only where light sampling runs, not at every hit of a scratched surface
    // (most of them see no scratch and are delta bounces). A material that picks one lobe by
    // it (`layer_mix = "stochastic"`) reads the bounce's BSDF-lobe number instead, and its
    // BSDF the place of that number within the pick's share: one stratified number picks the
    // layer and the component, as `union`'s sampling does with all the layers' lobes (drawn
    // apart, the two choices gave mirror-walled glints twice the variance).
    let u_layer = if material.reads_hit_context(wo_world, hit.ng) {
        if material.picks_lobe_by_lobe_number() {
            let u = sampler.peek(depth, LOBE_DIM);
            sampler.seek(depth, 1);
            Some(u)
        } else {
            Some(sampler.next_1d_hashed())
        }
    } else {
        sampler.seek(depth, 1);
        None
    };
    let reads_footprint = u_layer.is_some() && material.reads_footprint_at(wo_world, hit.ng);
    let (rd_here, chain) = if DIFFERENTIALS && reads_footprint {
        let (rd, chain) = differentials.resolve(&scene.geometry);
        (Some(rd), chain)
    } else {
        (None, None)
    };
    let view = HitView {
        wo: wo_world,
        rd: rd_here.as_ref(),
        u_layer,
        pixel: chain.map(|chain| PixelHit {
            shape: hit.shape,
            chain,
            offset: differentials.offset,
        }),
        origin_depth,
    };
    material.shade(hit, view, &mut worker.coverage)
}

/// A path vertex as next-event estimation reads it: the hit, its shading frame, the direction
/// toward the viewer in that frame, the BSDF there and the path throughput that reached it.
struct Vertex<'a, 'b> {
    hit: &'a SurfaceHit,
    frame: Frame,
    wo: Vec3,
    bsdf: &'a Bsdf<'b>,
    beta: Rgb,
}

/// Next-event estimation at a non-delta vertex: one light chosen uniformly, its sample weighted
/// by MIS (power heuristic) against BSDF sampling; a constant environment, left to BSDF
/// sampling, gives no sample when chosen (pbrt-v4's `allowIncompletePDF`). Returns the radiance
/// the path gains, `None` where the light's sample adds nothing or is occluded.
#[inline(always)]
fn direct_light(
    scene: &Scene,
    v: &Vertex<'_, '_>,
    sampler: &mut PixelSampler,
    worker: &mut Worker,
) -> Option<Rgb> {
    let (hit, frame, wo, bsdf) = (v.hit, v.frame, v.wo, v.bsdf);
    let shapes = scene.geometry.shapes();
    let n_lights = scene.lights.len();
    let light_select_pdf = 1.0 / n_lights as f32;
    let u_choice = sampler.next_1d();
    let u_light = sampler.next_2d();
    let index = ((u_choice * n_lights as f32) as usize).min(n_lights - 1);
    let light = &scene.lights[index];
    let ls = light.sample_li(hit.p, u_light, shapes)?;
    let wi = frame.to_local(ls.wi);
    let (f, pdf_bsdf) = bsdf.eval_for_light(wo, wi, ls.delta);
    let f = f * wi.z.abs();
    if f == Rgb::ZERO {
        return None;
    }
    let origin = scene.geometry.spawn_origin(hit.p, hit.ng, hit.shape, ls.wi);
    let t_max = if ls.dist.is_finite() {
        (ls.dist - (origin - hit.p).length()) * (1.0 - 1e-3)
    } else {
        f32::INFINITY
    };
    worker.rays += 1;
    let shadow = Ray {
        o: origin,
        d: ls.wi,
        t_max,
    };
    if scene.geometry.occluded(&shadow) {
        return None;
    }
    let pdf_light = light_select_pdf * ls.pdf;
    let w = if ls.delta {
        1.0
    } else {
        let pdf_bsdf = pdf_bsdf.unwrap_or_else(|| bsdf.pdf(wo, wi));
        power_heuristic(pdf_light, pdf_bsdf)
    };
    Some(v.beta * f * ls.radiance * (w / pdf_light))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::reflect;
    use crate::render::geometry::{Shape, ShapeGeometry, TriangleMesh};
    use crate::render::shading::{footprint_dp, refract_dir};

    fn geometry(g: ShapeGeometry) -> Geometry {
        Geometry::new(vec![Shape {
            geometry: g,
            material: 0,
            area_light: None,
        }])
    }

    /// Where a ray leaves a delta bounce off `hit` (shading normal), reflected or refracted
    /// into glass of index 1.5 from outside.
    fn bounce(d: Vec3, ns: Vec3, reflection: bool) -> Vec3 {
        let n = if d.dot(ns) < 0.0 { ns } else { -ns };
        if reflection {
            reflect(-d, n)
        } else {
            refract_dir(d, n, 1.0 / 1.5).unwrap()
        }
    }

    /// Deferred differentials ([`PathDifferentials`]) equal the ones worked out at every
    /// bounce, bit for bit, and so do the chains of delta bounces, whenever a hit asks for
    /// them: along paths of reflections, refractions and diffuse bounces inside and around the
    /// teapot and a sphere, asked at irregular bounces and longer than the pending capacity (so
    /// the records also flush as they fill up).
    #[test]
    fn deferred_differentials_equal_eager_ones() {
        let shapes = [
            geometry(ShapeGeometry::sphere(Vec3::ZERO, 1.0).unwrap()),
            geometry(ShapeGeometry::Mesh(TriangleMesh::teapot(12))),
        ];
        let bits = |rd: &RayDifferential| {
            [rd.rx_o, rd.rx_d, rd.ry_o, rd.ry_d].map(|v| v.to_array().map(f32::to_bits))
        };
        let (mut compared, mut longest, mut chains) = (0, 0, 0);
        for g in &shapes {
            for path in 0..30u32 {
                let a = path as f32 * 0.73;
                let o = Vec3::new(4.0 * a.cos(), 0.7 + 0.4 * (1.7 * a).sin(), 4.0 * a.sin());
                let d = (Vec3::new(0.05 * a.sin(), 0.7, 0.0) - o).normalize();
                let ex = d.cross(Vec3::Y).normalize();
                let ey = ex.cross(d);
                let camera = RayDifferential {
                    rx_o: o + 1e-3 * ex,
                    rx_d: (d + 1e-3 * ex).normalize(),
                    ry_o: o + 1e-3 * ey,
                    ry_d: (d + 1e-3 * ey).normalize(),
                };
                let mut eager = camera;
                let mut eager_chain = Some(0u64);
                let mut lazy = PathDifferentials::new(camera, Vec2::ZERO);
                let mut ray = Ray::new(o, d);
                let mut bounces = 0;
                while let Some(hit) = g.intersect(&ray) {
                    // The render loop's eager propagation (before `PathDifferentials`).
                    let k = bounces as u32 + 7 * path;
                    let delta = k % 5 != 3;
                    let n = if ray.d.dot(hit.ns) < 0.0 {
                        hit.ns
                    } else {
                        -hit.ns
                    };
                    let inside = ray.d.dot(hit.ng) > 0.0;
                    let eta = if inside { 1.5 } else { 1.0 / 1.5 };
                    // Refracted in, then reflected inside: long paths.
                    let refracted = refract_dir(ray.d, n, eta).filter(|_| delta && !inside);
                    let wi = match (delta, refracted) {
                        (true, Some(t)) => t.normalize(),
                        (true, None) => reflect(-ray.d, n),
                        // A diffuse bounce: some direction on the incoming side.
                        (false, _) => (n + 0.6 * hit.dpdu.normalize()).normalize(),
                    };
                    let eta_path = if refracted.is_some() { eta } else { 1.0 };
                    let (dpdx, dpdy) = footprint_dp(&hit, &eager);
                    let normals = if delta && g.has_curved_normals(hit.shape) {
                        offset_normals(g, &hit, n, dpdx, dpdy)
                    } else {
                        None
                    };
                    eager = spawn_differentials(
                        hit.p, dpdx, dpdy, ray.d, &eager, n, normals, wi, delta, eta_path,
                    );
                    // The render loop's chain of delta bounces (before it moved into
                    // `PathDifferentials`).
                    eager_chain = eager_chain
                        .filter(|_| delta)
                        .map(|chain| PixelHit::chain_after(chain, hit.shape, refracted.is_some()));
                    lazy.push(
                        g,
                        DeferredBounce {
                            hit,
                            n,
                            d_in: ray.d,
                            wi,
                            delta,
                            transmitted: refracted.is_some(),
                            eta: eta_path,
                        },
                    );
                    bounces += 1;
                    // Ask at irregular bounces, and never for some paths' first 12.
                    if k.wrapping_mul(2_654_435_761) % 7 < 2 && (path % 3 != 0 || bounces > 12) {
                        let (rd, chain) = lazy.resolve(g);
                        assert_eq!(bits(&rd), bits(&eager), "path {path}");
                        assert_eq!(chain, eager_chain, "path {path}");
                        chains += chain.is_some_and(|c| c != 0) as usize;
                        compared += 1;
                    }
                    if bounces == 3 * PathDifferentials::CAPACITY {
                        break;
                    }
                    ray = Ray::new(offset_origin(hit.p, hit.ng, wi), wi);
                }
                let (rd, chain) = lazy.resolve(g);
                assert_eq!(bits(&rd), bits(&eager), "path {path}, end");
                assert_eq!(chain, eager_chain, "path {path}, end");
                compared += 1;
                longest = longest.max(bounces);
            }
        }
        assert!(longest > 2 * PathDifferentials::CAPACITY, "{longest}");
        assert!(compared > 100, "{compared}");
        assert!(chains >= 10, "{chains} non-trivial chains compared");
    }

    /// A delta bounce's offset rays follow their neighbours: a ray offset by a small step
    /// from the central one, traced exactly to its own hit and bounced about its own shading
    /// normal, leaves in the direction the spawned differential says, on an analytic sphere
    /// and on the teapot's interpolated normals, for reflection and refraction at many
    /// angles. The locally flat rule (the hit's normal for every offset ray, `None`) misses
    /// the curvature's whole effect there.
    #[test]
    fn delta_bounce_differentials_follow_neighbour_rays_on_curved_surfaces() {
        let shapes = [
            (
                "sphere",
                geometry(ShapeGeometry::sphere(Vec3::ZERO, 1.0).unwrap()),
            ),
            (
                "teapot",
                geometry(ShapeGeometry::Mesh(TriangleMesh::teapot(12))),
            ),
        ];
        let step = 1e-3f32;
        let mut checked = 0;
        for (name, g) in &shapes {
            for i in 0..40 {
                // Rays from a ring of eye points toward the shape's middle, slightly off axis.
                let a = i as f32 * 0.61;
                let o = Vec3::new(4.0 * a.cos(), 0.8 + 0.5 * (1.3 * a).sin(), 4.0 * a.sin());
                let target = Vec3::new(0.1 * (2.0 * a).sin(), 0.7, 0.1 * a.cos());
                let d = (target - o).normalize();
                let Some(hit) = g.intersect(&Ray::new(o, d)) else {
                    continue;
                };
                let ex = d.cross(Vec3::Y).normalize();
                let ey = ex.cross(d);
                let rd = RayDifferential {
                    rx_o: o + step * ex,
                    rx_d: d,
                    ry_o: o + step * ey,
                    ry_d: d,
                };
                let (dpdx, dpdy) = footprint_dp(&hit, &rd);
                for reflection in [true, false] {
                    let wi = bounce(d, hit.ns, reflection);
                    let eta = if reflection { 1.0 } else { 1.0 / 1.5 };
                    let normals = offset_normals(g, &hit, hit.ns, dpdx, dpdy);
                    assert!(
                        normals.is_some(),
                        "{name}: curved surfaces have offset normals"
                    );
                    let spawn = |normals| {
                        spawn_differentials(
                            hit.p, dpdx, dpdy, d, &rd, hit.ns, normals, wi, true, eta,
                        )
                    };
                    let (curved, flat) = (spawn(normals), spawn(None));
                    for (o_off, got, got_flat) in [
                        (rd.rx_o, curved.rx_d, flat.rx_d),
                        (rd.ry_o, curved.ry_d, flat.ry_d),
                    ] {
                        let Some(h) = g.intersect(&Ray::new(o_off, d)) else {
                            continue;
                        };
                        if (h.shape, h.ng.dot(d) < 0.0) != (hit.shape, hit.ng.dot(d) < 0.0) {
                            continue;
                        }
                        let want = bounce(d, h.ns, reflection);
                        let spread = (want - wi).length();
                        assert!(spread > 1e-5, "{name}: the neighbour must turn ({spread})");
                        let err = (got - want).length();
                        let err_flat = (got_flat - want).length();
                        assert!(
                            err < 0.02 * spread,
                            "{name} ray {i} reflection {reflection}: off by {err} of {spread}"
                        );
                        assert!(
                            err_flat > 0.5 * spread,
                            "{name} ray {i}: the flat rule should miss ({err_flat} of {spread})"
                        );
                        checked += 1;
                    }
                }
            }
        }
        assert!(checked > 200, "{checked}");
        // Flat faces keep the hit's normal: a box has normals, all equal per face.
        let cube = geometry(ShapeGeometry::Mesh(TriangleMesh::cuboid()));
        assert!(shapes.iter().all(|(_, g)| g.has_curved_normals(0)));
        assert!(!cube.has_curved_normals(0));
        let ray = Ray::new(Vec3::new(0.3, 0.2, 5.0), -Vec3::Z);
        let hit = cube.intersect(&ray).unwrap();
        let normals = offset_normals(&cube, &hit, hit.ns, 0.1 * Vec3::X, 0.1 * Vec3::Y);
        assert_eq!(normals, None);
    }
}
