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
//!   the [`ShadingContext`]. They are worked out lazily (`path::PathDifferentials`): a bounce is
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
//! * **Two loops, one path**: a path's vertex is one function (`path::Path::land`) that two
//!   render loops drive: the one-path loop (the reference: each pixel's samples one after
//!   another, a path from its camera ray to its end) and the lane loop (`render.lanes`,
//!   `lanes`: [`LANES`] paths of a tile in flight, each stage run for all of them), which runs
//!   the vertices of diffuse, smooth dielectric (glTF's clear smooth glass included) and smooth
//!   conductor surfaces in SIMD lanes (`lane_vertex`, `land`'s operations as selects, bit for
//!   bit), and those of rough (GGX) ones, compensated or not, and of glTF's other BSDFs, in
//!   the same stages where that is measured to pay in the copy (AVX-512: all; AVX2: rough
//!   glass and metal, compensated glass; `lane_vertex::simd_ggx`). They give the same image
//!   bit for bit wherever no material reads a pixel's footprint (`tests/lanes.rs`).

mod lane_vertex;
mod lanes;
mod path;

use lane_vertex::simd_ggx;

pub use lanes::LANES;

pub use path::offset_normals;
use path::{
    camera_packet, camera_sample, traces_camera_packets, CameraHit, CameraSample, DeferredBounce,
    Path,
};

use crate::layers::CoverageCache;
use crate::math::{Ray, RayDifferential, Rgb, Vec2, Vec3};
use crate::render::bsdf::Bsdf;
use crate::render::film::Image;
use crate::render::geometry::{SurfaceHit, PACKET};
use crate::render::material::{HitView, Material};
use crate::render::scene::{Scene, NO_MATERIAL};
use crate::render::shading::{hit_context, ShadingContext};
use arrayvec::ArrayVec;
use rayon::prelude::*;
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
        render_tile_body::<true, { simd_ggx::NONE }>(scene, rect, pass.samples, worker)
    } else {
        render_tile_body::<false, { simd_ggx::NONE }>(scene, rect, pass.samples, worker)
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
/// ([`LoopCopy`]), running the GGX kinds `$simd_ggx` (a [`simd_ggx`] set) in SIMD lanes.
macro_rules! render_loop_copy {
    ($copy:ident, $name:ident, $simd_ggx:expr) => {
        $copy! {
            unsafe fn $name<const DIFFERENTIALS: bool>(
                scene: &Scene,
                rect: [u32; 4],
                samples: (u32, u32),
                worker: &mut Worker,
            ) -> Vec<Rgb> {
                render_tile_body::<DIFFERENTIALS, { $simd_ggx }>(scene, rect, samples, worker)
            }
        }
    };
}

// (The portable copy is the `render_tile_body` call in `render_tile`, with `simd_ggx::NONE`.)
render_loop_copy!(loop_copy_avx2, render_tile_avx2, simd_ggx::AVX2);
render_loop_copy!(loop_copy_avx512, render_tile_avx512, simd_ggx::ALL);

/// The tile's pixels' sums of the samples `samples`, with (`DIFFERENTIALS`,
/// `pass.differentials`) or without ray differentials; `SIMD_GGX`: the GGX kinds the lane
/// loop runs in SIMD lanes (a [`simd_ggx`] set).
#[inline(always)]
fn render_tile_body<const DIFFERENTIALS: bool, const SIMD_GGX: u32>(
    scene: &Scene,
    rect: [u32; 4],
    samples: (u32, u32),
    worker: &mut Worker,
) -> Vec<Rgb> {
    if scene.settings.lanes {
        return lanes::render_tile::<DIFFERENTIALS, SIMD_GGX>(scene, rect, samples, worker);
    }
    let [x0, y0, x1, y1] = rect;
    let mut out = Vec::with_capacity(((x1 - x0) * (y1 - y0)) as usize);
    for y in y0..y1 {
        for x in x0..x1 {
            out.push(render_pixel::<DIFFERENTIALS>(scene, x, y, samples, worker));
        }
    }
    out
}

/// The sum of the samples `first..end` of pixel `(x, y)` (box filter: uniform positions in the
/// pixel), added in sample order; divided by the spp, the pixel's value when they are all of
/// them. Where the pass traces packets (`path::traces_camera_packets`), in chunks of up to
/// [`PACKET`]: a chunk's camera rays are traced together (`path::camera_packet`), then its
/// paths run one after another, in sample order. The hits are the same, so the image is too.
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
    if !traces_camera_packets(scene, end - start) {
        for s in start..end {
            let sample = camera_sample::<DIFFERENTIALS>(scene, (x, y), pixel_index, s);
            let l = radiance::<DIFFERENTIALS>(scene, sample, CameraHit::Untraced, worker);
            add(l, worker);
        }
        return sum;
    }
    // (`ArrayVec`s: only what a chunk holds is written.)
    let mut samples = ArrayVec::<CameraSample, PACKET>::new();
    let mut hits = ArrayVec::<Option<SurfaceHit>, PACKET>::new();
    let mut first = start;
    while first < end {
        let n = (end - first).min(PACKET as u32);
        let chunk = (first, n as usize);
        camera_packet::<DIFFERENTIALS>(scene, (x, y), pixel_index, chunk, &mut samples, &mut hits);
        for (sample, hit) in samples.drain(..).zip(&hits) {
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
    camera: CameraSample,
    camera_hit: CameraHit,
    worker: &mut Worker,
) -> Rgb {
    let mut path = Path::new(camera);
    let mut hit = match camera_hit {
        CameraHit::Traced(hit) => hit,
        CameraHit::Untraced => scene.geometry.intersect(&path.ray),
    };
    while path
        .land::<DIFFERENTIALS, false>(scene, hit, worker)
        .goes_on
    {
        hit = scene.geometry.intersect(&path.ray);
    }
    path.l
}
