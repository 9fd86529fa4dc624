//! Cost of `eval` + `pdf` (two calls), of `eval_pdf` (one) and of `sample` for every BSDF, and of environment-map sampling.
//! The scratched glass with dielectric walls reads tables of the default sizes (smooth walls:
//! 17 MiB, which the lookups' cache misses make part of the cost), or, for smooth walls as
//! they render by default, traces the groove (`scratched_glass_traced`).
//! Each iteration processes a batch of 1024 precomputed random directions / sample points.
//!
//! `cargo bench -p striae --bench bsdf`

use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};
use rand::{Rng, SeedableRng};
use std::sync::Arc;
use striae::math::{Rgb, Vec2, Vec3};
use striae::precompute::profile::Profile;
use striae::precompute::wall_table::{WallTable, WallTableParams};
use striae::render::bsdf::{
    Bsdf, Conductor, ConductorIor, Dielectric, Diffuse, GlassWalls, RoughConductor,
    RoughDielectric, ScratchLobe, ScratchedGlassBsdf, TracedGroove, WallLobeTable,
};
use striae::render::envmap::EnvMap;
use striae::sampling::square_to_uniform_sphere;

const BATCH: usize = 1024;

fn bsdfs() -> Vec<(&'static str, Bsdf<'static>)> {
    let ConductorIor { eta, k } = ConductorIor::preset("gold").unwrap();
    vec![
        ("diffuse", Bsdf::Diffuse(Diffuse::new(Rgb::splat(0.8)))),
        ("dielectric", Bsdf::Dielectric(Dielectric::new(1.5))),
        ("conductor", Bsdf::Conductor(Conductor::new(eta, k))),
        (
            "rough_dielectric",
            Bsdf::RoughDielectric(RoughDielectric::new(1.5, 0.2)),
        ),
        (
            "rough_conductor",
            Bsdf::RoughConductor(RoughConductor::new(eta, k, 0.2)),
        ),
        ("scratched_glass_smooth", scratched_glass(0.0, false)),
        ("scratched_glass_traced", scratched_glass(0.0, true)),
        ("scratched_glass_rough", scratched_glass(0.3, false)),
    ]
}

/// Glass with two crossing scratches (coverages 0.3 and 0.25) whose round grooves have
/// dielectric walls of GGX `roughness` (METHOD.md 8.2): read from a table of the default
/// sizes, traced with 300 paths a direction (the lookups' cost does not depend on them), or
/// (`traced`, smooth walls) the groove traced at every sample.
fn scratched_glass(roughness: f64, traced: bool) -> Bsdf<'static> {
    let profile = Profile::parse("round:depth=0.3").unwrap();
    let params = WallTableParams {
        paths: 300,
        ..WallTableParams::new(profile, 1.5, roughness)
    };
    let walls = if traced {
        GlassWalls::Traced(Arc::new(TracedGroove::new(&params)))
    } else {
        GlassWalls::Table(Arc::new(WallLobeTable::new(
            &WallTable::compute(&params).unwrap(),
        )))
    };
    let lobe = |coverage: f32, beta: f32| ScratchLobe::new(coverage, beta.cos(), beta.sin());
    let lobes = [lobe(0.3, 0.4), lobe(0.25, 2.1)];
    Bsdf::ScratchedGlass(ScratchedGlassBsdf::new(
        1.5,
        Box::leak(Box::new(walls)),
        &lobes,
    ))
}

fn bench(c: &mut Criterion) {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(1);
    let mut dir = |upper: bool| {
        let mut w = square_to_uniform_sphere(Vec2::new(rng.random(), rng.random()));
        if upper {
            w.z = w.z.abs();
        }
        w
    };
    let wo: Vec<Vec3> = (0..BATCH).map(|_| dir(true)).collect();
    let wi: Vec<Vec3> = (0..BATCH).map(|_| dir(false)).collect();
    let wo_any: Vec<Vec3> = (0..BATCH).map(|_| dir(false)).collect();
    let us: Vec<(f32, Vec2)> = (0..BATCH)
        .map(|_| (rng.random(), Vec2::new(rng.random(), rng.random())))
        .collect();

    let mut g = c.benchmark_group("bsdf");
    g.throughput(Throughput::Elements(BATCH as u64));
    for (name, b) in bsdfs() {
        // Transmissive BSDFs are also queried from inside.
        let wo = if b.has_transmission() { &wo_any } else { &wo };
        if !b.is_delta() {
            g.bench_function(format!("{name}/eval+pdf"), |bench| {
                bench.iter(|| {
                    let mut acc = Rgb::ZERO;
                    for (o, i) in wo.iter().zip(&wi) {
                        acc += b.eval(*o, *i) * b.pdf(*o, *i);
                    }
                    black_box(acc)
                })
            });
        }
        if !b.is_delta() {
            g.bench_function(format!("{name}/eval_pdf"), |bench| {
                bench.iter(|| {
                    let mut acc = Rgb::ZERO;
                    for (o, i) in wo.iter().zip(&wi) {
                        let (f, p) = b.eval_pdf(*o, *i);
                        acc += f * p;
                    }
                    black_box(acc)
                })
            });
        }
        g.bench_function(format!("{name}/sample"), |bench| {
            bench.iter(|| {
                let mut acc = Rgb::ZERO;
                for (o, (ul, u)) in wo.iter().zip(&us) {
                    if let Some(s) = b.sample(*o, *ul, *u) {
                        acc += s.weight * s.pdf + s.wi;
                    }
                }
                black_box(acc)
            })
        });
    }

    // A 1024 x 512 environment map with structure.
    let (w, h) = (1024, 512);
    let px = (0..w * h)
        .map(|i| {
            Rgb::new(
                (i % w) as f32 / w as f32,
                0.5,
                ((i / w) as f32 * 0.1).sin().abs() * 3.0,
            )
        })
        .collect();
    let env = EnvMap::from_rgb(w, h, px).unwrap();
    g.bench_function("envmap_1024x512/sample", |bench| {
        bench.iter(|| {
            let mut acc = Rgb::ZERO;
            for (_, u) in &us {
                let (d, l, pdf) = env.sample(*u);
                acc += l * pdf + d;
            }
            black_box(acc)
        })
    });
    g.bench_function("envmap_1024x512/eval+pdf", |bench| {
        bench.iter(|| {
            let mut acc = Rgb::ZERO;
            for d in &wi {
                acc += env.eval(*d) * env.pdf(*d);
            }
            black_box(acc)
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
