//! End-to-end path tracing throughput on the built-in glass teapot scene (camera samples per
//! second; the CLI prints the same figure plus rays/s for a full 512 x 384 render). Also the
//! cost of one pixel sample's random numbers. The built-in scene is the scratched teapot
//! (setting 1); the smooth glass teapot of `scenes/glass-teapot.toml` (the scene of the speed
//! comparison with Mitsuba 3, BENCHMARKS.md)
//! runs at 128 x 96 x 4 spp with the default render loop (the widest copy the CPU runs), its
//! AVX2 copy (`Simd::Avx2`: what a CPU without AVX-512 runs) and its portable copy
//! (`Simd::Portable`: no AVX2), with the watertight triangle test and in the lane loop. Also a
//! pixel's camera numbers one sample at a time and in lanes. Run:
//! `cargo bench -p striae --bench render`.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use std::path::Path;
use striae::render::integrator::{render, render_with, Simd};
use striae::render::sampler::{PixelSampler, SamplerKind};
use striae::render::scene::{Overrides, Scene};

fn bench_render(c: &mut Criterion) {
    let mut g = c.benchmark_group("render");
    g.sample_size(10);
    for (w, h, spp) in [(128u32, 96u32, 4u32), (512, 384, 1)] {
        let o = Overrides {
            spp: Some(spp),
            resolution: Some((w, h)),
            seed: Some(0),
            max_depth: None,
            sampler: None,
            lanes: None,
        };
        let scene = Scene::parse(
            striae::render::scene::DEFAULT_SCENE,
            Path::new("glass-teapot.toml"),
            Path::new("."),
            &o,
        )
        .unwrap();
        g.throughput(Throughput::Elements(w as u64 * h as u64 * spp as u64));
        g.bench_function(format!("glass_teapot_{w}x{h}_{spp}spp"), |b| {
            b.iter(|| render(&scene, &|_| {}))
        });
    }
    // The smooth glass teapot, with each compiled copy of the render loop.
    let o = Overrides {
        spp: Some(4),
        resolution: Some((128, 96)),
        seed: Some(0),
        max_depth: None,
        sampler: None,
        lanes: None,
    };
    let smooth = Scene::parse(
        include_str!("../scenes/glass-teapot.toml"),
        Path::new("glass-teapot.toml"),
        Path::new("."),
        &o,
    )
    .unwrap();
    g.throughput(Throughput::Elements(128 * 96 * 4));
    for (name, simd) in [
        ("auto", Simd::Auto),
        ("avx2", Simd::Avx2),
        ("portable", Simd::Portable),
    ] {
        g.bench_function(format!("smooth_glass_teapot_128x96_4spp_{name}"), |b| {
            b.iter(|| render_with(&smooth, &|_| {}, simd))
        });
    }
    // The same with the watertight triangle test (`render.watertight`; the default is the fast
    // one).
    let watertight = Scene::parse(
        &include_str!("../scenes/glass-teapot.toml")
            .replace("[render]\n", "[render]\nwatertight = true\n"),
        Path::new("glass-teapot.toml"),
        Path::new("."),
        &o,
    )
    .unwrap();
    g.bench_function("smooth_glass_teapot_128x96_4spp_auto_watertight", |b| {
        b.iter(|| render(&watertight, &|_| {}))
    });
    // The same in the lane loop (`render.lanes`).
    let lanes = Scene::parse(
        include_str!("../scenes/glass-teapot.toml"),
        Path::new("glass-teapot.toml"),
        Path::new("."),
        &Overrides {
            lanes: Some(true),
            ..o
        },
    )
    .unwrap();
    g.bench_function("smooth_glass_teapot_128x96_4spp_auto_lanes", |b| {
        b.iter(|| render(&lanes, &|_| {}))
    });
    g.finish();

    let mut g = c.benchmark_group("sampler");
    g.throughput(Throughput::Elements(32));
    for kind in [SamplerKind::Sobol, SamplerKind::Independent] {
        g.bench_function(format!("32_dimensions_{}", kind.name()), |b| {
            let mut i = 0u32;
            b.iter(|| {
                i = i.wrapping_add(1);
                let mut s = PixelSampler::with_kind(kind, i as u64, i & 1023, 1);
                let mut acc = 0.0f32;
                for _ in 0..32 {
                    acc += s.next_1d();
                }
                acc
            })
        });
    }
    // A pixel's camera numbers for 32 samples: one sample at a time and in lanes.
    g.throughput(Throughput::Elements(32));
    g.bench_function("camera_dimensions_32_samples_one_at_a_time", |b| {
        let mut i = 0u64;
        b.iter(|| {
            i = i.wrapping_add(1);
            let mut acc = 0.0f32;
            for s in 0..32 {
                let mut p = PixelSampler::with_kind(SamplerKind::Sobol, i, s, 1);
                acc += p.next_1d() + p.next_1d() + p.next_1d() + p.next_1d();
            }
            acc
        })
    });
    g.bench_function("camera_dimensions_32_samples_lanes", |b| {
        let mut i = 0u64;
        b.iter(|| {
            i = i.wrapping_add(1);
            let (_, numbers) = PixelSampler::sobol_camera_lanes(i, 0, 1);
            numbers.iter().flatten().sum::<f32>()
        })
    });
    g.finish();
}

criterion_group!(benches, bench_render);
criterion_main!(benches);
