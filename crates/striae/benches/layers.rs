//! Scratch layers (METHOD.md section 5): point and footprint queries over 8 layers, and
//! rasterising 8 layers at 2048 x 2048. Run: `cargo bench -p striae --bench layers`.

use criterion::{black_box, criterion_group, criterion_main, Criterion};
use striae::layers::{LayerParams, LayerSet};
use striae::math::Vec2;

/// Query points spread over the texture (a fixed low-discrepancy sequence, R2).
fn points(n: usize) -> Vec<Vec2> {
    let (a1, a2) = (0.754_877_7f64, 0.569_840_3f64);
    (0..n)
        .map(|i| {
            Vec2::new(
                ((0.5 + a1 * i as f64) % 1.0) as f32,
                ((0.5 + a2 * i as f64) % 1.0) as f32,
            )
        })
        .collect()
}

fn queries(c: &mut Criterion) {
    for setting in [1, 2] {
        let set = LayerSet::new(LayerParams::setting(setting).unwrap(), 1).unwrap();
        let pts = points(1024);
        let mut g = c.benchmark_group(format!("layers/setting{setting}"));
        let mut i = 0;
        g.bench_function("point_query_8_layers", |b| {
            b.iter(|| {
                i = (i + 1) & 1023;
                black_box(set.scratched_mask(black_box(pts[i])))
            })
        });
        // A footprint the size of one pixel of a 1024-pixel-wide view of the texture, rotated.
        let (dx, dy) = (Vec2::new(0.8, 0.3) / 1024.0, Vec2::new(-0.3, 0.9) / 1024.0);
        let mut out = [0.0f32; 8];
        g.bench_function("footprint_query_8_layers", |b| {
            b.iter(|| {
                i = (i + 1) & 1023;
                set.coverage_all(black_box(pts[i]), dx, dy, &mut out);
                black_box(out[0])
            })
        });
        g.finish();
    }
}

fn rasterise(c: &mut Criterion) {
    let mut g = c.benchmark_group("layers/raster");
    g.sample_size(10);
    for setting in [1, 2] {
        let set = LayerSet::new(LayerParams::setting(setting).unwrap(), 1).unwrap();
        g.bench_function(format!("setting{setting}_8_layers_2048"), |b| {
            b.iter(|| {
                (0..set.len())
                    .map(|k| set.rasterize(k, 2048).unwrap().mean())
                    .sum::<f64>()
            })
        });
    }
    g.finish();
}

criterion_group!(benches, queries, rasterise);
criterion_main!(benches);
