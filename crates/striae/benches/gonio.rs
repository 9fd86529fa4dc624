//! Criterion bench of the exact groove tracer (`striae gonio`, METHOD.md 8.1): paths per
//! second for the seed's walls (diffuse, Schlick per hit), mirror walls and smooth and rough
//! glass walls. Throughput is reported in paths.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use striae::optics::fresnel::FresnelLaw;
use striae::precompute::groove::{trace_groove, GonioSettings, GrooveWalls};
use striae::precompute::profile::Profile;

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("gonio");
    g.sample_size(10);
    let base = GonioSettings {
        theta_i: 30f64.to_radians(),
        phi_i: 20f64.to_radians(),
        paths: 2_000_000,
        bins: 32,
        ..GonioSettings::default()
    };
    for (name, spec, s) in [
        (
            "v90_diffuse_schlick",
            "v:angle=90",
            GonioSettings {
                walls: GrooveWalls::Diffuse,
                ..base.clone()
            },
        ),
        (
            "v90_specular_conductor",
            "v:angle=90",
            GonioSettings {
                walls: GrooveWalls::Specular,
                fresnel_law: FresnelLaw::Conductor { eta: 0.2, k: 3.9 },
                ..base.clone()
            },
        ),
        (
            "round_diffuse_schlick",
            "round:depth=0.4",
            GonioSettings {
                walls: GrooveWalls::Diffuse,
                ..base.clone()
            },
        ),
        (
            "v90_dielectric",
            "v:angle=90",
            GonioSettings {
                walls: GrooveWalls::Dielectric,
                ..base.clone()
            },
        ),
        (
            "v90_dielectric_rough",
            "v:angle=90",
            GonioSettings {
                walls: GrooveWalls::Dielectric,
                roughness: 0.3,
                ..base.clone()
            },
        ),
    ] {
        let profile = Profile::parse(spec).unwrap();
        g.throughput(Throughput::Elements(s.paths));
        g.bench_function(name, |b| {
            b.iter(|| trace_groove(&profile, &s, &|_| {}).unwrap())
        });
    }
    g.finish();
}

criterion_group! {
    name = benches;
    // No HTML plots: criterion's plotters backend needs system fonts the CI machine may lack.
    config = Criterion::default().without_plots();
    targets = bench
}
criterion_main!(benches);
