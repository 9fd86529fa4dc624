//! Times striae's ray queries alone, on rays read from a file: the striae half of
//! `scripts/bench_traversal.py`, which times Mitsuba 3 (Embree) on the same rays of the same
//! scene, so the traversal can be compared apart from the rest of the path tracer.
//!
//! ```sh
//! cargo run --release -p striae --example trace_rays -- SCENE.toml RAYS.f32 [REPEATS]
//! ```
//!
//! `RAYS.f32` is little-endian `f32`, six per ray (origin, direction), `t_max` infinite. On one
//! thread, compiled like the render loop copy `striae render` runs on this CPU (AVX-512, AVX2 +
//! FMA or portable, `LoopCopy::chosen`), it runs `Geometry::intersect` (closest hit with the
//! whole `SurfaceHit`), `Geometry::intersect_coherent` on runs of [`PACKET`] consecutive rays
//! (`intersect_packets`: as the render loop traces a pixel's camera rays; rays that share no
//! origin, such as secondary rays, fall back to one by one) and `Geometry::occluded` (any hit)
//! over all rays `REPEATS` times (default 7) and prints, per query, the median rate and the
//! number of rays that hit, one `key=value` line each.

use arrayvec::ArrayVec;
use std::error::Error;
use std::path::Path;
use std::time::Instant;
use striae::math::{Ray, Vec3};
use striae::render::geometry::PACKET;
use striae::render::scene::{Overrides, Scene};

#[derive(Clone, Copy, PartialEq)]
enum Query {
    Intersect,
    IntersectPackets,
    Occluded,
}

/// Runs `query` over `rays`: the number of hits and a checksum the optimiser cannot drop.
/// Plain `for` loops: an iterator adapter (`filter_map`, `count`) is compiled out of line,
/// and out of line the queries lose the copy's target features (7 % slower for `intersect`,
/// 7-13 % for `occluded`).
#[inline(always)]
fn run(scene: &Scene, rays: &[Ray], query: Query) -> (usize, f32) {
    let (mut hits, mut sum) = (0usize, 0.0f32);
    match query {
        Query::Intersect => {
            for ray in rays {
                if let Some(hit) = scene.geometry.intersect(ray) {
                    hits += 1;
                    sum += hit.t + hit.uv.x + hit.ns.x;
                }
            }
        }
        Query::IntersectPackets => {
            let mut out = ArrayVec::new();
            for chunk in rays.chunks(PACKET) {
                scene.geometry.intersect_coherent(chunk, &mut out);
                for hit in out.iter().flatten() {
                    hits += 1;
                    sum += hit.t + hit.uv.x + hit.ns.x;
                }
            }
        }
        Query::Occluded => {
            for ray in rays {
                hits += scene.geometry.occluded(ray) as usize;
            }
        }
    }
    (hits, sum)
}

striae::loop_copy_avx2! {
    unsafe fn run_avx2(scene: &Scene, rays: &[Ray], query: Query) -> (usize, f32) {
        run(scene, rays, query)
    }
}

striae::loop_copy_avx512! {
    unsafe fn run_avx512(scene: &Scene, rays: &[Ray], query: Query) -> (usize, f32) {
        run(scene, rays, query)
    }
}

/// The queries compiled as the render loop's copy that `striae render` runs on this CPU.
fn run_best(scene: &Scene, rays: &[Ray], query: Query) -> (usize, f32) {
    use striae::render::integrator::{LoopCopy, Simd};
    match LoopCopy::chosen(Simd::Auto) {
        // SAFETY: `chosen` picks only copies whose features the CPU has.
        #[cfg(target_arch = "x86_64")]
        LoopCopy::Avx512 => unsafe { run_avx512(scene, rays, query) },
        // SAFETY: as above.
        #[cfg(target_arch = "x86_64")]
        LoopCopy::Avx2 => unsafe { run_avx2(scene, rays, query) },
        _ => run(scene, rays, query),
    }
}

fn main() -> Result<(), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        return Err("usage: trace_rays SCENE.toml RAYS.f32 [REPEATS]".into());
    }
    let repeats: usize = match args.get(3) {
        Some(r) => r
            .parse()
            .map_err(|_| format!("REPEATS: not a count: {r}"))?,
        None => 7,
    };
    let scene = Scene::load(Path::new(&args[1]), &Overrides::default())?;
    let bytes = std::fs::read(&args[2]).map_err(|e| format!("{}: {e}", args[2]))?;
    if bytes.len() % 24 != 0 {
        return Err(format!("{}: not a whole number of rays (6 f32 each)", args[2]).into());
    }
    let rays: Vec<Ray> = bytes
        .chunks_exact(24)
        .map(|c| {
            let f =
                |i: usize| f32::from_le_bytes([c[4 * i], c[4 * i + 1], c[4 * i + 2], c[4 * i + 3]]);
            Ray::new(Vec3::new(f(0), f(1), f(2)), Vec3::new(f(3), f(4), f(5)))
        })
        .collect();
    for (query, name) in [
        (Query::Intersect, "intersect"),
        (Query::IntersectPackets, "intersect_packets"),
        (Query::Occluded, "occluded"),
    ] {
        let mut seconds = Vec::with_capacity(repeats.max(1));
        let mut hits = 0;
        for _ in 0..repeats.max(1) {
            let start = Instant::now();
            let (h, sum) = run_best(&scene, &rays, query);
            std::hint::black_box(sum);
            seconds.push(start.elapsed().as_secs_f64());
            hits = h;
        }
        seconds.sort_by(f64::total_cmp);
        let median = seconds[seconds.len() / 2];
        println!(
            "query={name} rays={} hits={hits} seconds={median:.6} mrays_per_s={:.3}",
            rays.len(),
            rays.len() as f64 / median / 1e6
        );
    }
    Ok(())
}
