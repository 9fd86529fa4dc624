//! Rays per second of `Geometry::intersect` (closest hit) and `Geometry::occluded` (any hit) on
//! the Utah teapot tessellated at 64 x 64 quads per patch (~260k triangles), for the 8-wide BVH
//! with each triangle test (`TriangleTest`) and obvhs' binary BVH, with coherent camera rays and
//! incoherent random rays. Single-threaded.
//!
//! Time is the benchmark thread's **CPU time** (`/proc/thread-self/schedstat`), not wall time:
//! the development machine is shared by several engineers compiling at once, and wall time there
//! measures the scheduler more than the code. (Falls back to wall time where the file is missing.)
//!
//! `cargo bench -p striae --bench bvh`; results in BENCHMARKS.md, "Precompute, layers, BSDFs, BVH".

use std::time::Instant;

use criterion::measurement::{Measurement, ValueFormatter};
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use striae::math::{Ray, Vec2, Vec3};
use striae::render::geometry::{
    BvhKind, Geometry, Shape, ShapeGeometry, TriangleMesh, TriangleTest,
};
use striae::sampling::square_to_uniform_sphere;

const SUBDIVISIONS: u32 = 64;

/// CPU time of the calling thread in nanoseconds (wall time if schedstat is unavailable).
fn thread_cpu_ns() -> u64 {
    static START: std::sync::OnceLock<Instant> = std::sync::OnceLock::new();
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()
        .and_then(|s| s.split_whitespace().next()?.parse().ok())
        .unwrap_or_else(|| START.get_or_init(Instant::now).elapsed().as_nanos() as u64)
}

/// Criterion measurement: thread CPU time.
struct ThreadCpuTime;

struct CpuFormatter;

impl ValueFormatter for CpuFormatter {
    fn scale_values(&self, _typical: f64, values: &mut [f64]) -> &'static str {
        values.iter_mut().for_each(|v| *v /= 1e6);
        "ms (cpu)"
    }
    fn scale_throughputs(
        &self,
        _typical: f64,
        throughput: &Throughput,
        values: &mut [f64],
    ) -> &'static str {
        let n = match throughput {
            Throughput::Elements(n) | Throughput::Bytes(n) | Throughput::BytesDecimal(n) => {
                *n as f64
            }
        };
        values.iter_mut().for_each(|v| *v = n / (*v * 1e-9) / 1e6);
        "Mrays/s (cpu)"
    }
    fn scale_for_machines(&self, _values: &mut [f64]) -> &'static str {
        "ns"
    }
}

impl Measurement for ThreadCpuTime {
    type Intermediate = u64;
    type Value = u64;
    fn start(&self) -> u64 {
        thread_cpu_ns()
    }
    fn end(&self, start: u64) -> u64 {
        thread_cpu_ns().saturating_sub(start)
    }
    fn add(&self, a: &u64, b: &u64) -> u64 {
        a + b
    }
    fn zero(&self) -> u64 {
        0
    }
    fn to_f64(&self, v: &u64) -> f64 {
        *v as f64
    }
    fn formatter(&self) -> &dyn ValueFormatter {
        &CpuFormatter
    }
}

fn teapot_shapes() -> Vec<Shape> {
    vec![Shape {
        geometry: ShapeGeometry::Mesh(TriangleMesh::teapot(SUBDIVISIONS)),
        material: 0,
        area_light: None,
    }]
}

/// A 256 x 256 pinhole camera looking at the teapot, filling most of the frame.
fn coherent_rays() -> Vec<Ray> {
    let (w, h) = (256, 256);
    let eye = Vec3::new(2.0, -7.0, 3.5);
    let target = Vec3::new(0.3, 0.0, 1.4);
    let fwd = (target - eye).normalize();
    let right = fwd.cross(Vec3::Z).normalize();
    let up = right.cross(fwd);
    let tan_half = (20.0f32).to_radians().tan();
    let mut rays = Vec::with_capacity(w * h);
    for j in 0..h {
        for i in 0..w {
            let x = (2.0 * (i as f32 + 0.5) / w as f32 - 1.0) * tan_half;
            let y = (1.0 - 2.0 * (j as f32 + 0.5) / h as f32) * tan_half;
            rays.push(Ray::new(eye, (fwd + x * right + y * up).normalize()));
        }
    }
    rays
}

/// 65536 rays with origins uniform in a ball of radius 4 around the teapot and uniform directions
/// (like secondary bounces).
fn incoherent_rays() -> Vec<Ray> {
    let mut rng = Pcg64::seed_from_u64(1);
    (0..65536)
        .map(|_| {
            let o = Vec3::new(0.0, 0.0, 1.5)
                + 4.0
                    * rng.random::<f32>().cbrt()
                    * square_to_uniform_sphere(Vec2::new(rng.random(), rng.random()));
            Ray::new(
                o,
                square_to_uniform_sphere(Vec2::new(rng.random(), rng.random())),
            )
        })
        .collect()
}

fn bench(c: &mut Criterion<ThreadCpuTime>) {
    let shapes = teapot_shapes();
    let triangles = match &shapes[0].geometry {
        ShapeGeometry::Mesh(m) => m.triangle_count(),
        _ => unreachable!(),
    };
    let mut geometries = Vec::new();
    for (kind, test) in [
        (BvhKind::Bvh8, TriangleTest::Fast),
        (BvhKind::Bvh8, TriangleTest::Watertight),
        (BvhKind::Bvh2, TriangleTest::Watertight),
    ] {
        let name = format!("{kind:?}-{test:?}");
        // Single-threaded build, so the thread's CPU time is the build's.
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let (g, cpu_ns, wall) = pool.install(|| {
            let (cpu, wall) = (thread_cpu_ns(), Instant::now());
            let g = Geometry::with_bvh(shapes.clone(), kind, test);
            (g, thread_cpu_ns() - cpu, wall.elapsed())
        });
        eprintln!(
            "{name}: built over {triangles} triangles in {:.0} ms cpu ({:.0} ms wall, one thread)",
            cpu_ns as f64 / 1e6,
            wall.as_secs_f64() * 1e3
        );
        geometries.push((name, g));
    }
    for (name, rays) in [
        ("coherent", coherent_rays()),
        ("incoherent", incoherent_rays()),
    ] {
        let hit_fraction =
            rays.iter().filter(|r| geometries[0].1.occluded(r)).count() as f64 / rays.len() as f64;
        eprintln!(
            "{name}: {:.1}% of {} rays hit",
            100.0 * hit_fraction,
            rays.len()
        );
        let mut group = c.benchmark_group(format!("bvh/{name}"));
        group.throughput(Throughput::Elements(rays.len() as u64));
        group.sample_size(10);
        for (kind, g) in &geometries {
            group.bench_with_input(BenchmarkId::new("intersect", kind), &rays, |b, rays| {
                b.iter(|| rays.iter().filter(|r| g.intersect(r).is_some()).count())
            });
            group.bench_with_input(BenchmarkId::new("occluded", kind), &rays, |b, rays| {
                b.iter(|| rays.iter().filter(|r| g.occluded(r)).count())
            });
        }
        group.finish();
    }
}

criterion_group! {
    name = benches;
    // No plots: the plotters backend needs fonts the build machines lack.
    config = Criterion::default().without_plots().with_measurement(ThreadCpuTime);
    targets = bench
}
criterion_main!(benches);
