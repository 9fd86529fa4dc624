//! Cost per camera sample of scratched glass against smooth glass on the same scene (target:
//! at most 1.3x): the setting-1 glass teapot (Fig. 6 b, mostly background) and the
//! setting-1 plate close-up (Fig. 8 a, glass fills the frame), each rendered with the smooth
//! dielectric and the scratched material with its three coverage modes: `footprint` (the
//! default: METHOD.md section 6, one exact coverage per pixel and chain of delta bounces,
//! cached footprint tiles elsewhere), `sample` (the exact footprint of every sample) and
//! `point`; and `lean`, the default coverage with the tapered groove's lean (`lean = true`,
//! BENCHMARKS.md, "The tapered groove's lean"). Single-threaded, 128 x 96 pixels, 16 spp;
//! every render starts with empty caches.
//!
//! `cargo bench -p striae --bench scratched`; the standing figures (`scripts/scratched_cost.py`
//! at 512 x 384) are in BENCHMARKS.md, "Scratched glass over smooth glass".

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use std::path::Path;
use striae::render::scene::{Overrides, Scene};

const SCENES: [(&str, &str); 2] = [
    (
        "teapot-s1",
        include_str!("../scenes/glass-teapot-setting1.toml"),
    ),
    (
        "closeup-s1",
        include_str!("../scenes/glass-plate-closeup.toml"),
    ),
];

/// The scene text with its glass material replaced: `smooth`, or scratched with a coverage mode,
/// or `lean`.
fn variant(text: &str, kind: &str) -> String {
    let start = text.find("[materials.glass]").expect("glass material");
    let end = text.find("[[shapes]]").expect("shapes");
    let material = match kind {
        "smooth" => "[materials.glass]\ntype = \"dielectric\"\nior = 1.5\n\n".to_string(),
        "point" | "sample" => text[start..end].replace(
            "layer_mix = \"max\"",
            &format!("layer_mix = \"max\"\ncoverage = \"{kind}\""),
        ),
        "lean" => {
            text[start..end].replace("layer_mix = \"max\"", "layer_mix = \"max\"\nlean = true")
        }
        _ => text[start..end].to_string(),
    };
    format!("{}{}{}", &text[..start], material, &text[end..])
}

fn bench(c: &mut Criterion) {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let o = Overrides {
        spp: Some(16),
        resolution: Some((128, 96)),
        seed: Some(1),
        max_depth: None,
        sampler: None,
        lanes: None,
    };
    let mut g = c.benchmark_group("scratched");
    g.sample_size(10);
    g.throughput(Throughput::Elements(128 * 96 * 16));
    for (name, text) in SCENES {
        for kind in ["smooth", "footprint", "sample", "point", "lean"] {
            let scene =
                Scene::parse(&variant(text, kind), Path::new(name), Path::new("."), &o).unwrap();
            g.bench_with_input(BenchmarkId::new(name, kind), &scene, |b, s| {
                b.iter(|| pool.install(|| striae::render::integrator::render(s, &|_| {})))
            });
        }
    }
    g.finish();
}

criterion_group! {
    name = benches;
    // No plots: criterion's plotters backend needs a system font this machine may lack.
    config = Criterion::default().without_plots();
    targets = bench
}
criterion_main!(benches);
