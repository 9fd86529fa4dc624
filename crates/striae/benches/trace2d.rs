//! Criterion bench of the 2D scratch tracer (METHOD.md section 3): a reduced version of the
//! seed's table (90-degree V-groove, diffuse walls, N_r = 100), the full table with the
//! optional kernel estimator, and mirror walls. Throughput is
//! reported in walks ("paths"). The full seed table is timed with `striae precompute`
//! (BENCHMARKS.md, "Precompute, layers, BSDFs, BVH").

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use striae::precompute::profile::Profile;
use striae::precompute::trace2d::{trace, Estimator, TraceSettings, Walls};

fn bench(c: &mut Criterion) {
    let profile = Profile::parse("v:angle=90").unwrap();
    let mut g = c.benchmark_group("trace2d");
    g.sample_size(10);
    for (name, s) in [
        (
            "v90_diffuse_m64_n1000_nr100",
            TraceSettings {
                walls: Walls::Diffuse,
                m: 64,
                n: 1000,
                nr: 100,
                ..TraceSettings::default()
            },
        ),
        (
            // The seed's full table with the optional kernel estimator ("paths" are the
            // equivalent N M N_r walks of the seed's scheme).
            "v90_diffuse_kernel_m256_n10000_nr100",
            TraceSettings {
                walls: Walls::Diffuse,
                estimator: Estimator::Kernel,
                ..TraceSettings::default()
            },
        ),
        (
            "v90_specular_m256_n10000",
            TraceSettings {
                walls: Walls::Specular,
                m: 256,
                n: 10_000,
                ..TraceSettings::default()
            },
        ),
    ] {
        g.throughput(Throughput::Elements(s.total_paths()));
        g.bench_function(name, |b| b.iter(|| trace(&profile, &s, &|_| {}).unwrap()));
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
