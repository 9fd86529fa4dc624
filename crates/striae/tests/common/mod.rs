//! Helpers shared by the scene tests.
// (Each test binary uses some of these helpers.)
#![allow(dead_code)]

use std::path::Path;
use striae::render::film::Image;
use striae::render::integrator::{render, RenderStats};
use striae::render::scene::{Overrides, Scene};

/// A scene from TOML text (named `test.toml`, relative paths from the working folder); panics
/// with the loader's message if it does not parse.
pub fn scene(text: &str) -> Scene {
    Scene::parse(
        text,
        Path::new("test.toml"),
        Path::new("."),
        &Overrides::default(),
    )
    .unwrap_or_else(|e| panic!("{e}"))
}

/// Render `scene` in a rayon pool of exactly `threads` workers.
pub fn render_with_threads(scene: &Scene, threads: usize) -> (Image, RenderStats) {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(|| render(scene, &|_| {}))
}

/// Render `scene` with 1 and with 3 worker threads, assert the images are bit-identical and
/// trace the same number of rays, and return the image.
pub fn assert_bit_identical_across_thread_counts(scene: &Scene) -> Image {
    let (a, sa) = render_with_threads(scene, 1);
    let (b, sb) = render_with_threads(scene, 3);
    assert!(a
        .pixels
        .iter()
        .zip(&b.pixels)
        .all(|(x, y)| x.to_array().map(f32::to_bits) == y.to_array().map(f32::to_bits)));
    assert_eq!(sa.rays, sb.rays);
    a
}

/// The roots of `f` on `[a, b]`: each sign change between `n` equal steps, refined by 60
/// bisections.
pub fn roots(f: impl Fn(f64) -> f64, a: f64, b: f64, n: usize) -> Vec<f64> {
    let x = |k: usize| a + (b - a) * k as f64 / n as f64;
    let mut out = Vec::new();
    for k in 0..n {
        let (mut x0, mut x1) = (x(k), x(k + 1));
        if f(x0).signum() == f(x1).signum() {
            continue;
        }
        for _ in 0..60 {
            let m = 0.5 * (x0 + x1);
            if f(x0).signum() == f(m).signum() {
                x0 = m;
            } else {
                x1 = m;
            }
        }
        out.push(0.5 * (x0 + x1));
    }
    out
}
