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
