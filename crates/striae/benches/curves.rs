//! Scratches as curves (METHOD.md 9.1): loading an SVG of 10^5 segments, building its curve
//! set, and the point and footprint queries on a swirl pattern.
//! Run: `cargo bench -p striae --bench curves`.

use criterion::{black_box, criterion_group, criterion_main, Criterion};
use glam::DVec2;
use striae::curves::patterns::Pattern;
use striae::curves::stroke::StrokeStyle;
use striae::curves::{svg, CurveSet};

/// An SVG of 10^4 paths of 10 cubic Béziers each, every cubic flattened to about 1 segment
/// (10^5 segments in all at width 0.2 in a 1000-unit canvas).
pub fn big_svg() -> String {
    let mut s = String::from(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="1000" height="1000" viewBox="0 0 1000 1000">"#,
    );
    for i in 0..10_000u32 {
        let (x, y) = ((i % 100) as f64 * 10.0, (i / 100) as f64 * 10.0);
        s.push_str(&format!(r#"<path d="M{x} {y}"#));
        for k in 0..10 {
            let x0 = x + k as f64 * 0.9;
            s.push_str(&format!(
                " C{} {} {} {} {} {}",
                x0 + 0.3,
                y + 0.001,
                x0 + 0.6,
                y + 0.001,
                x0 + 0.9,
                y
            ));
        }
        s.push_str(r#"" fill="none" stroke="black" stroke-width="0.2"/>"#);
    }
    s.push_str("</svg>");
    s
}

fn load(c: &mut Criterion) {
    let text = big_svg();
    let style = StrokeStyle::default();
    let d = svg::parse(text.as_bytes(), "big.svg", &style).unwrap();
    let segments: usize = d.polylines.iter().map(|p| p.points.len() - 1).sum();
    let set = CurveSet::new(&d.polylines, d.to_uv()).unwrap();
    eprintln!(
        "big.svg: {} paths, {segments} segments, {} bytes in the set ({:.0} a segment)",
        d.paths,
        set.bytes(),
        set.bytes() as f64 / segments as f64
    );
    let mut g = c.benchmark_group("curves/svg_1e5_segments");
    g.sample_size(10);
    g.bench_function("parse", |b| {
        b.iter(|| black_box(svg::parse(text.as_bytes(), "big.svg", &style).unwrap()))
    });
    g.bench_function("build_set", |b| {
        b.iter(|| black_box(CurveSet::new(&d.polylines, d.to_uv()).unwrap()))
    });
}

fn queries(c: &mut Criterion) {
    let swirl = Pattern::Swirl {
        count: 1700,
        radius: [0.1, 0.4],
        arc: [20.0, 90.0],
        width: 0.0006,
        seed: 5,
    };
    let lines = swirl.polylines(&StrokeStyle::default()).unwrap();
    let set = CurveSet::new(&lines, DVec2::ONE).unwrap();
    let (a1, a2) = (0.754_877_7f64, 0.569_840_3f64);
    let pts: Vec<DVec2> = (0..1024)
        .map(|i| DVec2::new((0.5 + a1 * i as f64) % 1.0, (0.5 + a2 * i as f64) % 1.0))
        .collect();
    let mut g = c.benchmark_group("curves/swirl_1700");
    let mut i = 0;
    g.bench_function("point_query", |b| {
        b.iter(|| {
            i = (i + 1) & 1023;
            black_box(set.at_point(black_box(pts[i])))
        })
    });
    // One pixel of a 1024-pixel-wide view of the texture, rotated (as the layers' bench).
    let (dx, dy) = (
        DVec2::new(0.8, 0.3) / 1024.0,
        DVec2::new(-0.3, 0.9) / 1024.0,
    );
    g.bench_function("footprint_query", |b| {
        b.iter(|| {
            i = (i + 1) & 1023;
            black_box(set.footprint(black_box(pts[i]), dx, dy, 0.5))
        })
    });
}

criterion_group!(benches, load, queries);
criterion_main!(benches);
